"""Pose files (KITTI, TUM, 3DMatch .log, Open3D pose graphs), saved results, and scoring
a transformation obtained elsewhere."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import open3d as o3d
import pytest
from helpers import motion_matrix, partial_views, random_motion, synthetic_scene

from o3d_rpointhop import RegistrationResult, evaluate, register, register_multiway
from o3d_rpointhop.cli import EXIT_ERROR, EXIT_OK, EXIT_UNRELIABLE, main
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.datasets.threedmatch import read_gt_log
from o3d_rpointhop.poses import (
    read_matrix,
    read_pose_graph,
    read_poses,
    write_matrix,
    write_pose_graph,
    write_poses,
)
from o3d_rpointhop.registration import MultiwayResult
from o3d_rpointhop.transforms import apply_transform

POSES = [motion_matrix(*random_motion(seed, 3.0)) for seed in range(4)]


@pytest.mark.parametrize("fmt", ["kitti", "tum"])
def test_trajectories_round_trip(tmp_path, fmt):
    write_poses(tmp_path / "t.txt", POSES, fmt)
    back = read_poses(tmp_path / "t.txt", fmt)
    assert len(back) == 4
    for a, b in zip(POSES, back, strict=True):
        np.testing.assert_allclose(b, a, atol=1e-8)


def test_poses_at_survey_coordinates_read_back_to_the_bit(tmp_path):
    """Every digit is written: KITTI, the 3DMatch log and a single matrix read back
    the same doubles; TUM's translation too (its rotation passes through a quaternion,
    exact to rounding). Written with nine digits, a pose at a UTM northing moved points
    by millimetres."""
    survey = np.array([452_310.123456789, 5_211_870.987654321, 312.456789123])
    poses = [pose.copy() for pose in POSES]
    for pose in poses:
        pose[:3, 3] += survey
    for fmt in ("kitti", "3dmatch"):
        write_poses(tmp_path / "t.txt", poses, fmt)
        back = read_poses(tmp_path / "t.txt", fmt)
        back = list(back.values()) if isinstance(back, dict) else back
        for a, b in zip(poses, back, strict=True):
            np.testing.assert_array_equal(b, a)
    write_poses(tmp_path / "t.txt", poses, "tum")
    for a, b in zip(poses, read_poses(tmp_path / "t.txt", "tum"), strict=True):
        np.testing.assert_array_equal(b[:3, 3], a[:3, 3])
        np.testing.assert_allclose(b[:3, :3], a[:3, :3], rtol=0, atol=1e-15)
    write_matrix(tmp_path / "m.txt", poses[1])
    np.testing.assert_array_equal(read_matrix(tmp_path / "m.txt"), poses[1])


def test_formats_hold_the_published_layouts(tmp_path):
    pose = np.eye(4)
    pose[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]  # 90 deg about z
    pose[:3, 3] = [1.0, 2.0, 3.0]
    write_poses(tmp_path / "k.txt", [pose], "kitti")
    assert np.loadtxt(tmp_path / "k.txt").tolist() == [0, -1, 0, 1, 1, 0, 0, 2, 0, 0, 1, 3]
    write_poses(tmp_path / "t.txt", [pose], "tum", timestamps=[12.5])
    stamp, *xyz, qx, qy, qz, qw = np.loadtxt(tmp_path / "t.txt")
    assert stamp == 12.5 and xyz == [1, 2, 3]
    np.testing.assert_allclose([qx, qy, qz, qw], [0, 0, np.sqrt(0.5), np.sqrt(0.5)])
    write_poses(tmp_path / "a.log", [pose], "3dmatch", pairs=[(3, 7)], n_fragments=60)
    assert (tmp_path / "a.log").read_text().splitlines()[0] == "3 7 60"
    # The benchmark's own gt.log reader reads what is written.
    np.testing.assert_allclose(read_gt_log(tmp_path / "a.log")[(3, 7)], pose)
    np.testing.assert_allclose(read_poses(tmp_path / "a.log", "3dmatch")[(3, 7)], pose)


def test_bad_pose_files_and_poses_are_refused(tmp_path):
    (tmp_path / "short.txt").write_text("1 0 0 0 0 1 0 0 0 0 1\n")
    with pytest.raises(ValueError, match="line 1: 11 numbers, expected 12"):
        read_poses(tmp_path / "short.txt", "kitti")
    (tmp_path / "words.txt").write_text("# a comment\n1 0 0 x 0 1 0 0 0 0 1 0\n")
    with pytest.raises(ValueError, match="line 2: not numbers"):
        read_poses(tmp_path / "words.txt", "kitti")
    (tmp_path / "quat.txt").write_text("0 1 2 3 0 0 0 2\n")
    with pytest.raises(ValueError, match="unit length"):
        read_poses(tmp_path / "quat.txt", "tum")
    scaled = np.diag([2.0, 2.0, 2.0, 1.0])
    with pytest.raises(ValueError, match=r"poses\[0\]: not a rigid"):
        write_poses(tmp_path / "s.txt", [scaled])
    mirror = np.diag([1.0, 1.0, -1.0, 1.0])
    with pytest.raises(ValueError, match="not a rigid"):
        write_matrix(tmp_path / "m.txt", mirror)
    (tmp_path / "bad.log").write_text("0 1 2\n1 0 0 0\n0 1 0\n0 0 1 0\n0 0 0 1\n")
    with pytest.raises(ValueError, match="record 0: not a header and a 4 x 4 matrix"):
        read_poses(tmp_path / "bad.log", "3dmatch")
    with pytest.raises(ValueError, match="format must be one of"):
        write_poses(tmp_path / "x.txt", POSES, "g2o")
    with pytest.raises(FileNotFoundError):
        read_matrix(tmp_path / "missing.txt")
    write_matrix(tmp_path / "m.txt", POSES[1])
    np.testing.assert_allclose(read_matrix(tmp_path / "m.txt"), POSES[1], atol=1e-10)


@pytest.fixture(scope="module")
def multiway():
    scans, _ = partial_views(3, seed=1)
    return scans, register_multiway(scans, random_state=0)


def test_multiway_results_and_pose_graphs_round_trip(tmp_path, multiway):
    scans, result = multiway
    result.save(tmp_path / "r.json")
    back = MultiwayResult.load(tmp_path / "r.json")
    for a, b in zip(result.poses, back.poses, strict=True):
        np.testing.assert_array_equal(a, b)
    assert back.edges == result.edges and back.unconnected == result.unconnected
    assert back.pairs.keys() == result.pairs.keys()
    # What the report derives from the saved edges and pairs: the same, here none.
    chain = dataclasses.replace(back, edges=back.edges[:2])
    assert back.unverified() == result.unverified() == {}
    assert chain.unverified() == dataclasses.replace(result, edges=result.edges[:2]).unverified()
    assert sorted(chain.unverified()) == [1, 2]  # 0-1 and 0-2: each a leaf
    assert len(back.pose_graph.edges) == len(result.pose_graph.edges)
    np.testing.assert_array_equal(
        back.pose_graph.edges[0].information, result.pose_graph.edges[0].information
    )
    np.testing.assert_allclose(  # the loaded result merges like the original
        np.asarray(back.merge(scans).points), np.asarray(result.merge(scans).points)
    )
    write_pose_graph(tmp_path / "g.json", result.pose_graph)
    graph = o3d.io.read_pose_graph(str(tmp_path / "g.json"))
    assert len(graph.nodes) == len(result.pose_graph.nodes)
    np.testing.assert_allclose(
        read_pose_graph(tmp_path / "g.json").nodes[1].pose, graph.nodes[1].pose
    )
    with pytest.raises(ValueError, match="not a saved RegistrationResult"):
        RegistrationResult.load(tmp_path / "r.json")
    # A damaged file is refused by name: a pose that is not a 4 x 4 matrix, a part left out.
    body = json.loads((tmp_path / "r.json").read_text())
    body["poses"][0] = [[1.0, 0.0], [0.0, 1.0]]
    (tmp_path / "pose.json").write_text(json.dumps(body))
    with pytest.raises(ValueError, match=r"pose.json: expected a finite \(4, 4\) array"):
        MultiwayResult.load(tmp_path / "pose.json")
    body = json.loads((tmp_path / "r.json").read_text())
    del body["edges"]
    (tmp_path / "cut.json").write_text(json.dumps(body))
    with pytest.raises(ValueError, match="cut.json: a damaged saved result"):
        MultiwayResult.load(tmp_path / "cut.json")


def test_registration_results_round_trip(tmp_path):
    target = make_object(1500, shape_seed=5, sample_seed=1)
    rot, shift = random_motion(2, 0.2)
    result = register(make_object(1500, shape_seed=5, sample_seed=2) @ rot.T + shift, target)
    result.save(tmp_path / "r.json")
    back = RegistrationResult.load(tmp_path / "r.json")
    np.testing.assert_array_equal(back.transformation, result.transformation)
    np.testing.assert_array_equal(back.correspondence_set, result.correspondence_set)
    assert [s.name for s in back.steps] == [s.name for s in result.steps]
    np.testing.assert_array_equal(
        back.steps[0].correspondence_set, result.steps[0].correspondence_set
    )
    assert back.steps[0].info == json.loads(json.dumps(result.steps[0].info))
    assert (back.fitness, back.converged, back.ambiguous, back.preparation_seconds) == (
        result.fitness,
        result.converged,
        result.ambiguous,
        result.preparation_seconds,
    )
    # A file saved before results kept their preparation time loads with none.
    body = json.loads((tmp_path / "r.json").read_text())
    del body["preparation_seconds"]
    (tmp_path / "older.json").write_text(json.dumps(body))
    assert RegistrationResult.load(tmp_path / "older.json").preparation_seconds == 0.0
    (tmp_path / "bad.json").write_text('{"kind": "RegistrationResult", "format": 1}')
    with pytest.raises(ValueError, match="damaged saved result"):
        RegistrationResult.load(tmp_path / "bad.json")
    (tmp_path / "text.json").write_text("not json")
    with pytest.raises(ValueError, match="not a readable saved result"):
        RegistrationResult.load(tmp_path / "text.json")
    saved = (tmp_path / "r.json").read_text()
    for cut in (len(saved) // 3, len(saved) // 2, len(saved) - 2):  # inside any token
        (tmp_path / "cut.json").write_text(saved[:cut])
        with pytest.raises(ValueError, match=r"JSON cut short"):
            RegistrationResult.load(tmp_path / "cut.json")
    # A binary file, a file of another format version and provenance JSON cannot hold
    # are each refused with what is wrong, not a decoder's traceback.
    (tmp_path / "binary.json").write_bytes(b"\xff\xfe\x00binary")
    with pytest.raises(ValueError, match="not UTF-8 text"):
        RegistrationResult.load(tmp_path / "binary.json")
    body["format"] = 99
    (tmp_path / "future.json").write_text(json.dumps(body))
    with pytest.raises(ValueError, match="result format 99, expected 1"):
        RegistrationResult.load(tmp_path / "future.json")
    with pytest.raises(TypeError, match="cannot write object to JSON"):
        result.save(tmp_path / "odd.json", provenance={"made by": object()})
    # numpy values in the provenance are written as JSON's own numbers and lists.
    result.save(tmp_path / "np.json", provenance={"seed": np.int64(3), "shift": np.zeros(2)})
    assert json.loads((tmp_path / "np.json").read_text())["provenance"] == {
        "seed": 3,
        "shift": [0.0, 0.0],
    }


def test_evaluate_scores_a_given_transformation_like_open3d():
    target = make_object(2000, shape_seed=3, sample_seed=1)
    rot, shift = random_motion(6, 0.5)
    truth = np.linalg.inv(motion_matrix(rot, shift))
    source = make_object(2000, shape_seed=3, sample_seed=2) @ rot.T + shift
    good = evaluate(source, target, truth, distance=0.02)
    peer = o3d.pipelines.registration.evaluate_registration(
        o3d.geometry.PointCloud(o3d.utility.Vector3dVector(source)),
        o3d.geometry.PointCloud(o3d.utility.Vector3dVector(target)),
        0.02,
        truth,
    )
    assert good.fitness == pytest.approx(peer.fitness, abs=1e-12)
    assert good.inlier_rmse == pytest.approx(peer.inlier_rmse, rel=1e-9)
    assert len(good.correspondence_set) == len(peer.correspondence_set)
    assert good.converged and good.steps[0].name == "evaluate"
    far = motion_matrix(np.eye(3), np.array([5.0, 0.0, 0.0])) @ truth
    bad = evaluate(source, target, far)
    assert bad.fitness == 0.0 and not bad.converged
    with pytest.raises(ValueError, match="The .distance. parameter of evaluate must be"):
        evaluate(source, target, truth, distance=-1.0)
    with pytest.raises(ValueError, match="4x4"):
        evaluate(source, target, np.eye(3))


def test_evaluate_against_a_3dmatch_gt_log_takes_the_fragments_record(tmp_path, capsys):
    """``--truth gt.log``: the record of the two fragments the names end in, either way
    round, and with ``gt.info`` beside it the official RMSE and verdict; no record, or a
    name without a number, is one clear error."""
    target = make_object(1500, shape_seed=8, sample_seed=1)
    rot, shift = random_motion(4, 0.4)
    source = make_object(1500, shape_seed=8, sample_seed=2) @ rot.T + shift
    np.save(tmp_path / "cloud_bin_3.npy", source)
    np.save(tmp_path / "cloud_bin_7.npy", target)
    truth = np.linalg.inv(motion_matrix(rot, shift))  # fragment 3 into fragment 7
    off = motion_matrix(np.eye(3), np.array([0.3, 0.0, 0.0])) @ truth
    write_matrix(tmp_path / "off.txt", off)
    args = [
        "evaluate",
        str(tmp_path / "cloud_bin_3.npy"),
        str(tmp_path / "cloud_bin_7.npy"),
        "--truth",
        str(tmp_path / "gt.log"),
        "--json",
    ]
    information = np.diag([4.0, 4.0, 4.0, 1.0, 1.0, 1.0])
    for key, matrix in (((7, 3), truth), ((3, 7), np.linalg.inv(truth))):
        write_poses(tmp_path / "gt.log", [matrix], "3dmatch", pairs=[key], n_fragments=9)
        (tmp_path / "gt.info").write_text(
            f"{key[0]} {key[1]} 9\n" + "\n".join(" ".join(map(str, r)) for r in information)
        )
        for transform, registered in ((truth, True), (off, False)):
            write_matrix(tmp_path / "T.txt", transform)
            main([*args, "--transform", str(tmp_path / "T.txt")])
            summary = json.loads(capsys.readouterr().out)
            assert summary["record_3dmatch"] == list(key)
            assert summary["registered_3dmatch"] is registered
            # The official error of a pure shift is the shift (information 4 I on it).
            want = 0.0 if registered else 0.3
            assert summary["rmse_3dmatch"] == pytest.approx(want, abs=1e-9)
            assert summary["translation_error"] == pytest.approx(want, abs=1e-9)
    (tmp_path / "gt.info").unlink()  # without it: the errors, not the official test
    assert main([*args, "--transform", str(tmp_path / "T.txt")]) == EXIT_UNRELIABLE  # off
    summary = json.loads(capsys.readouterr().out)
    assert "rmse_3dmatch" not in summary and summary["translation_error"] > 0.29
    write_poses(tmp_path / "gt.log", [truth], "3dmatch", pairs=[(7, 4)])
    assert main([*args, "--transform", str(tmp_path / "T.txt")]) == EXIT_ERROR
    assert "holds no record of fragments 3 and 7" in capsys.readouterr().err
    np.save(tmp_path / "scan.npy", source)
    named = [args[0], str(tmp_path / "scan.npy"), *args[2:], "--transform", str(tmp_path / "T.txt")]
    assert main(named) == EXIT_ERROR
    assert "the name ends in no number" in capsys.readouterr().err


def test_evaluate_and_pose_outputs_from_the_command_line(tmp_path, capsys, multiway):
    target = make_object(1500, shape_seed=8, sample_seed=1)
    rot, shift = random_motion(3, 0.4)
    source = make_object(1500, shape_seed=8, sample_seed=2) @ rot.T + shift
    np.save(tmp_path / "s.npy", source)
    np.save(tmp_path / "t.npy", target)
    truth = np.linalg.inv(motion_matrix(rot, shift))
    write_matrix(tmp_path / "truth.txt", truth)
    off = truth.copy()
    off[0, 3] += 0.01
    write_matrix(tmp_path / "off.txt", off)
    args = ["evaluate", str(tmp_path / "s.npy"), str(tmp_path / "t.npy")]
    assert (
        main(
            [
                *args,
                "--transform",
                str(tmp_path / "off.txt"),
                "--truth",
                str(tmp_path / "truth.txt"),
                "--json",
            ]
        )
        == EXIT_OK
    )
    summary = json.loads(capsys.readouterr().out)
    assert summary["translation_error"] == pytest.approx(0.01, abs=1e-9)
    assert summary["rotation_error_deg"] == pytest.approx(0.0, abs=1e-3)  # arccos near 1
    # Within the resolution (fitness measured at half of it, as register() measures).
    assert summary["converged"] and summary["fitness"] > 0.1
    assert summary["distance"] == pytest.approx(0.5 * summary["voxel_size"])
    write_matrix(tmp_path / "far.txt", motion_matrix(np.eye(3), np.array([9.0, 0, 0])))
    assert main([*args, "--transform", str(tmp_path / "far.txt")]) == EXIT_UNRELIABLE
    (tmp_path / "bad.txt").write_text("1 2 3\n")
    assert main([*args, "--transform", str(tmp_path / "bad.txt")]) == EXIT_ERROR
    assert "3 numbers, expected 4" in capsys.readouterr().err

    scans, _ = multiway
    names = []
    for k, scan in enumerate(scans):
        np.save(tmp_path / f"v{k}.npy", scan)
        names.append(str(tmp_path / f"v{k}.npy"))
    outputs = {
        "--pose-graph": tmp_path / "g.json",
        "--trajectory": tmp_path / "traj.txt",
        "--result": tmp_path / "multi.json",
    }
    flat = [str(v) for item in outputs.items() for v in item]
    command = ["reconstruct", *names, "-o", str(tmp_path / "m.ply"), *flat]
    assert main([*command, "--trajectory-format", "tum"]) == EXIT_OK
    saved = MultiwayResult.load(tmp_path / "multi.json")
    trajectory = read_poses(tmp_path / "traj.txt", "tum")
    for pose, written in zip(saved.poses, trajectory, strict=True):
        np.testing.assert_allclose(written, pose, atol=1e-7)
    assert len(read_pose_graph(tmp_path / "g.json").nodes) == 3


def test_global_steps_keep_their_matches_in_the_caller_s_coordinates(tmp_path):
    """The global step's descriptor matches come back as point pairs of the clouds as
    given (far from the origin too), and the ones its estimate explains are marked."""
    target = make_object(1500, shape_seed=5, sample_seed=1) + [1000.0, -500.0, 20.0]
    rot, shift = random_motion(2, 0.2)
    source = (make_object(1500, shape_seed=5, sample_seed=2) + [1000.0, -500.0, 20.0]) @ rot.T
    result = register(source, target)
    step = result.steps[0]
    assert step.matches.shape == (step.info["candidate_matches"], 2, 3)
    # Every matched source point is a point near the source cloud, every target point
    # near the target (the global clouds are downsampled from them).
    from scipy.spatial import cKDTree

    res = result.voxel_size
    assert cKDTree(source).query(step.matches[:, 0])[0].max() < 2 * res
    assert cKDTree(target).query(step.matches[:, 1])[0].max() < 2 * res
    moved = apply_transform(step.matches[:, 0], step.transformation)
    near = np.linalg.norm(moved - step.matches[:, 1], axis=1) < step.distance
    np.testing.assert_array_equal(step.match_inliers, near)
    assert step.match_inliers.sum() == step.info["inlier_matches"]
    result.save(tmp_path / "r.json")
    back = RegistrationResult.load(tmp_path / "r.json").steps[0]
    np.testing.assert_array_equal(back.matches, step.matches)
    np.testing.assert_array_equal(back.match_inliers, step.match_inliers)
    assert result.steps[1].matches is None  # ICP matches no descriptors


def test_kitti_keeps_a_line_for_a_scan_without_a_pose(tmp_path):
    """Line k is scan k: a scan without a pose is a line of 12 nan, read back as None;
    TUM and 3DMatch name their scans, so None is refused there; a line only partly nan is
    damaged."""
    turn = np.eye(4)
    turn[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    write_poses(tmp_path / "k.txt", [np.eye(4), None, turn], "kitti")
    assert (tmp_path / "k.txt").read_text().splitlines()[1] == " ".join(["nan"] * 12)
    back = read_poses(tmp_path / "k.txt", "kitti")
    assert back[1] is None
    np.testing.assert_array_equal(back[2], turn)
    for fmt in ("tum", "3dmatch"):
        with pytest.raises(ValueError, match="only KITTI files mark a scan without a pose"):
            write_poses(tmp_path / f"x.{fmt}", [np.eye(4), None], fmt)
    with pytest.raises(ValueError, match="no poses to write"):
        write_poses(tmp_path / "none.txt", [None, None], "kitti")
    (tmp_path / "half.txt").write_text("nan " * 6 + "0 " * 6 + "\n")
    with pytest.raises(ValueError, match="not a finite 4x4 matrix"):
        read_poses(tmp_path / "half.txt", "kitti")


def test_trajectories_keep_scan_k_in_every_format_and_convert(tmp_path, capsys):
    """Scan k's pose at scan k, scan 2 without one: KITTI marks it with nan, TUM and
    .log leave it out and name the others; each reads back as the same list, and
    ``poses convert`` turns any of the three into any other."""
    from o3d_rpointhop.poses import read_trajectory, write_trajectory

    poses = [np.eye(4), motion_matrix(*random_motion(1)), None, motion_matrix(*random_motion(2))]
    for fmt in ("kitti", "tum", "3dmatch"):
        path = tmp_path / f"t.{fmt}"
        write_trajectory(path, poses, fmt)
        back = read_trajectory(path, fmt, n_scans=4)
        assert back[2] is None and len(back) == 4
        for got, want in zip(back, poses, strict=True):
            if want is not None:
                np.testing.assert_allclose(got, want, atol=1e-8)
    assert (tmp_path / "t.tum").read_text().split()[0::8] == ["0", "1", "3"]
    headers = (tmp_path / "t.3dmatch").read_text().splitlines()[::5]
    assert headers == ["0 0 4", "0 1 4", "0 3 4"]
    assert read_trajectory(tmp_path / "t.3dmatch", "3dmatch")[2] is None  # n from the header
    out = tmp_path / "out.txt"
    args = ["poses", "convert", str(tmp_path / "t.tum"), str(out), "--from", "tum", "--to"]
    assert main([*args, "kitti", "--scans", "5"]) == EXIT_OK
    lines = out.read_text().splitlines()
    assert len(lines) == 5 and lines[2] == lines[4] == " ".join(["nan"] * 12)
    assert "3 of 5 scans' poses converted" in capsys.readouterr().out
    np.testing.assert_allclose(read_trajectory(out, "kitti")[3], poses[3], atol=1e-8)
    write_trajectory(tmp_path / "c.tum", poses, "tum", comment="made by a test")
    assert (tmp_path / "c.tum").read_text().startswith("# made by a test\n")
    assert read_trajectory(tmp_path / "c.tum", "tum")[3] is not None
    with pytest.raises(ValueError, match="only TUM"):
        write_trajectory(tmp_path / "c.txt", poses, "kitti", comment="x")
    assert main([*args, "kitti", "--scans", "2"]) == EXIT_ERROR
    assert "poses of more than 2 scans" in capsys.readouterr().err


def test_reconstruct_writes_several_trajectories_in_one_run(tmp_path):
    scans, _ = partial_views(3, seed=2)
    names = []
    for k, scan in enumerate(scans):
        np.save(tmp_path / f"s{k}.npy", scan)
        names.append(str(tmp_path / f"s{k}.npy"))
    out = [tmp_path / "k.txt", tmp_path / "t.txt", tmp_path / "p.log"]
    args = [
        "reconstruct",
        *names,
        "-o",
        str(tmp_path / "m.ply"),
        "--poses",
        str(tmp_path / "p.json"),
    ]
    for path, fmt in zip(out, ("kitti", "tum", "3dmatch"), strict=True):
        args += ["--trajectory", str(path), "--trajectory-format", fmt]
    assert main(args) == EXIT_OK
    summary = json.loads((tmp_path / "p.json").read_text())
    from o3d_rpointhop.poses import read_trajectory

    for path, fmt in zip(out, ("kitti", "tum", "3dmatch"), strict=True):
        for got, want in zip(read_trajectory(path, fmt), summary["poses"], strict=True):
            np.testing.assert_allclose(got, np.array(want), atol=1e-7)
    record = json.loads(out[1].read_text().splitlines()[0].removeprefix("# o3d-rpointhop "))
    assert record == summary["provenance"]
    bad = args[:-4] + ["--trajectory-format", "tum"]  # three files, two formats
    assert main(bad) == 2
    # Without --trajectory-format each file's suffix says: .log is 3DMatch's, else KITTI.
    by_suffix = [tmp_path / "k2.txt", tmp_path / "p2.log"]
    again = args[:8] + ["--trajectory", str(by_suffix[0]), "--trajectory", str(by_suffix[1])]
    assert main(again) == EXIT_OK
    assert by_suffix[0].read_text() == out[0].read_text()
    assert by_suffix[1].read_text() == out[2].read_text()
    # So does poses convert, both ways, with neither format named.
    convert = ["poses", "convert", str(out[2]), str(tmp_path / "c.txt")]
    assert main(convert) == EXIT_OK
    assert (tmp_path / "c.txt").read_text() == out[0].read_text()
    assert main(["poses", "convert", str(out[0]), str(tmp_path / "c.log")]) == EXIT_OK
    assert (tmp_path / "c.log").read_text() == out[2].read_text()


def test_poses_score_counts_the_gt_log_pairs_a_reconstruction_registers(tmp_path, capsys):
    """``poses score``: reconstruct's poses of a 3DMatch-style folder against its gt.log,
    the official test pair by pair; a fragment unplaced or moved loses its pairs, and
    a log without its gt.info is one clear error."""
    synthetic_scene(tmp_path, "room", ids=(0, 4, 10), seed=5)
    folder, gt = tmp_path / "fragments" / "room", tmp_path / "benchmarks" / "3DMatch" / "room"
    poses = tmp_path / "p.json"
    assert (
        main(["reconstruct", str(folder), "-o", str(tmp_path / "m.ply"), "--poses", str(poses)])
        == 0
    )
    capsys.readouterr()
    score = ["poses", "score", str(poses), "--truth", str(gt / "gt.log")]
    assert main(score) == EXIT_OK
    assert "2 of 2 gt.log pairs registered" in capsys.readouterr().out
    summary = json.loads(poses.read_text())
    for change, registered, placed in (("unplace", 0, 2), ("move", 1, 3)):
        edited = json.loads(json.dumps(summary))
        if change == "unplace":
            edited["poses"][1] = None  # cloud_bin_4: both of its pairs are lost
        else:
            edited["poses"][2][0][3] += 1.0  # cloud_bin_10 a metre off: pair (4, 10) lost
        poses.write_text(json.dumps(edited))
        assert main([*score, "--json"]) == EXIT_OK
        out = json.loads(capsys.readouterr().out)
        assert (out["registered"], out["pairs"]) == (registered, 2)
        assert (out["placed_with_pairs"], out["fragments_with_pairs"]) == (placed, 3)
        assert [r["pair"] for r in out["rmse"]] == [[0, 4], [4, 10]]
    edited["poses"][2] = [[1.0, 0.0], [0.0, 1.0]]
    poses.write_text(json.dumps(edited))
    assert main(score) == EXIT_ERROR
    assert "cloud_bin_10.ply is not a finite 4x4 matrix" in capsys.readouterr().err
    poses.write_text(json.dumps(summary))
    (gt / "gt.info").unlink()
    assert main(score) == EXIT_ERROR
    assert "the official test needs each pair's information" in capsys.readouterr().err


def test_a_log_path_is_a_3dmatch_trajectory_unless_told_otherwise(tmp_path):
    """``format="auto"`` (the default of every trajectory function): 3DMatch for a
    ``.log`` path, any case, KITTI for any other; a named format wins."""
    from o3d_rpointhop.poses import pose_format, read_trajectory, write_trajectory

    assert pose_format("a/b/gt.LOG") == "3dmatch"
    assert pose_format("poses.txt") == pose_format("poses") == "kitti"
    assert pose_format("poses.log", "kitti") == "kitti"
    assert pose_format("poses.txt", "tum") == "tum"
    with pytest.raises(ValueError, match="format must be one of"):
        pose_format("poses.txt", "g2o")
    poses = [np.eye(4), None, POSES[1]]
    write_trajectory(tmp_path / "t.log", poses)
    assert (tmp_path / "t.log").read_text().splitlines()[::5] == ["0 0 3", "0 2 3"]
    back = read_trajectory(tmp_path / "t.log")
    assert back[1] is None
    np.testing.assert_allclose(back[2], POSES[1], atol=1e-12)
    write_poses(tmp_path / "k.txt", POSES[:2])
    assert np.loadtxt(tmp_path / "k.txt").shape == (2, 12)
    assert list(read_poses(tmp_path / "t.log")) == [(0, 0), (0, 2)]
    write_poses(tmp_path / "k.log", POSES[:2], "kitti")  # named: KITTI in a .log file
    assert np.loadtxt(tmp_path / "k.log").shape == (2, 12)


def test_pose_files_that_say_too_little_or_too_much_get_one_clear_line(tmp_path):
    """Empty and cut files, counts that do not match, a .log into several scans, a
    missing file and an unknown format: each refused with what is wrong."""
    from o3d_rpointhop.poses import log_records, read_trajectory, write_trajectory

    (tmp_path / "empty.txt").write_text("# only a comment\n\n")
    for format in ("kitti", "tum"):
        with pytest.raises(ValueError, match="no poses in this file"):
            read_poses(tmp_path / "empty.txt", format)
    (tmp_path / "none.txt").write_text(" ".join(["nan"] * 12) + "\n")
    with pytest.raises(ValueError, match="only scans without one"):
        read_poses(tmp_path / "none.txt", "kitti")
    write_poses(tmp_path / "a.log", POSES[:2], "3dmatch")
    lines = (tmp_path / "a.log").read_text().splitlines()
    (tmp_path / "cut.log").write_text("\n".join(lines[:-1]) + "\n")
    with pytest.raises(ValueError, match="expected records of 5 lines, got 9 lines"):
        log_records(tmp_path / "cut.log", 4)
    with pytest.raises(ValueError, match="3 timestamps for 2 poses"):
        write_poses(tmp_path / "t.txt", POSES[:2], "tum", timestamps=[0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="1 pairs for 2 poses"):
        write_poses(tmp_path / "p.log", POSES[:2], "3dmatch", pairs=[(0, 1)])
    write_poses(tmp_path / "two.log", POSES[:2], "3dmatch", pairs=[(0, 1), (2, 3)])
    with pytest.raises(ValueError, match=r"records into several scans \(\[0, 2\]\)"):
        read_trajectory(tmp_path / "two.log", "3dmatch")
    with pytest.raises(FileNotFoundError, match="no such file"):
        read_poses(tmp_path / "nowhere.txt")
    for bad in (
        lambda: read_poses(tmp_path / "a.log", "g2o"),
        lambda: read_trajectory(tmp_path / "a.log", "g2o"),
        lambda: write_poses(tmp_path / "x.txt", POSES, "g2o"),
    ):
        with pytest.raises(ValueError, match="format must be one of"):
            bad()
    # TUM timestamps that are not scan numbers: the poses in file order.
    write_poses(tmp_path / "s.txt", POSES[:3], "tum", timestamps=[0.5, 1.25, 3.0])
    back = read_trajectory(tmp_path / "s.txt", "tum")
    assert len(back) == 3 and all(p is not None for p in back)
    np.testing.assert_allclose(back[1], POSES[1], atol=1e-6)
    write_trajectory(tmp_path / "k.txt", [POSES[0], None, POSES[2]], "kitti")
    assert read_trajectory(tmp_path / "k.txt", "kitti", n_scans=5)[3:] == [None, None]
    with pytest.raises(ValueError, match="poses of more than 2 scans"):
        read_trajectory(tmp_path / "k.txt", "kitti", n_scans=2)


def test_pose_graph_files_are_json_and_hold_nodes(tmp_path):
    graph = o3d.pipelines.registration.PoseGraph()
    with pytest.raises(ValueError, match="Open3D writes pose graphs as .json files"):
        write_pose_graph(tmp_path / "g.txt", graph)
    with pytest.raises(FileNotFoundError, match="no such file"):
        read_pose_graph(tmp_path / "nowhere.json")
    write_pose_graph(tmp_path / "empty.json", graph)
    with pytest.raises(ValueError, match="no pose graph nodes"):
        read_pose_graph(tmp_path / "empty.json")
