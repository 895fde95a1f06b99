"""The commands: fit, describe, demo, register, reconstruct."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import open3d as o3d
import pytest
from helpers import moved_pair_files, partial_views, write_points

from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.cli import main
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.io import read_cloud


@pytest.mark.slow
def test_reconstruct_command(tmp_path, capsys):
    import json

    from o3d_rpointhop.cli import EXIT_OK, EXIT_UNRELIABLE, main

    scans, _ = partial_views(3, seed=1)
    names = []
    for k, scan in enumerate(scans):
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(scan))
        cloud.paint_uniform_color([0.1 * (k + 1), 0.5, 0.9])
        cloud.estimate_normals()
        o3d.io.write_point_cloud(str(tmp_path / f"s{k}.ply"), cloud)
        names.append(str(tmp_path / f"s{k}.ply"))
    out, poses = tmp_path / "merged.ply", tmp_path / "poses.json"
    assert main(["reconstruct", *names, "-o", str(out), "--poses", str(poses)]) == EXIT_OK
    summary = json.loads(poses.read_text())
    assert summary["unconnected"] == [] and len(summary["poses"]) == 3

    # Every point of every scan, with the scans' own colours and normals.
    merged = o3d.io.read_point_cloud(str(out))
    assert len(merged.points) == sum(len(s) for s in scans)
    assert merged.has_normals()
    colours = {tuple(c) for c in np.asarray(merged.colors).round(2)}
    assert colours == {(0.1, 0.5, 0.9), (0.2, 0.5, 0.9), (0.3, 0.5, 0.9)}
    pose = np.array(summary["poses"][1])
    first = len(scans[0])
    np.testing.assert_allclose(  # scan 1's normals turned with it
        np.asarray(merged.normals)[first : first + 5],
        np.asarray(o3d.io.read_point_cloud(names[1]).normals)[:5] @ pose[:3, :3].T,
        atol=1e-6,
    )
    args = ["--output-voxel-size", "0.05", "--colour-by-scan"]
    assert main(["reconstruct", *names, "-o", str(out), *args]) == EXIT_OK
    merged = o3d.io.read_point_cloud(str(out))
    assert 100 < len(merged.points) < sum(len(s) for s in scans) / 2
    # Each scan's colour is there (voxels shared by two scans blend theirs).
    colours = {tuple(c) for c in np.asarray(merged.colors).round(2)}
    assert {(0.12, 0.47, 0.71), (1.0, 0.5, 0.05), (0.17, 0.63, 0.17)} <= colours
    np.save(tmp_path / "other.npy", make_object(1700, shape_seed=77) * 0.8 + 0.3)
    status = main(["reconstruct", *names, str(tmp_path / "other.npy"), "-o", str(out)])
    assert status == EXIT_UNRELIABLE
    err = capsys.readouterr().err
    # The scan of something else is named with why it was left out.
    assert re.search(r"left out: \S*other\.npy: no pair fit: the best, with \S+, has edge", err)


@pytest.mark.slow
def test_reconstruct_reads_folders_and_patterns_and_keeps_line_k_for_scan_k(tmp_path, capsys):
    """A folder of scans (with a note beside them) and a quoted pattern give the same
    scans by name; with a scan of something else among them, the KITTI trajectory keeps
    one line per scan, that scan's a line of nan, while TUM leaves it out."""
    from o3d_rpointhop.cli import EXIT_UNRELIABLE
    from o3d_rpointhop.poses import read_poses

    folder = tmp_path / "scans"
    folder.mkdir()
    scans, _ = partial_views(3, seed=1)
    np.save(folder / "a0.npy", scans[0])
    np.save(folder / "b1.npy", make_object(1700, shape_seed=77) * 0.8 + 0.3)  # no overlap
    np.save(folder / "c2.npy", scans[1])
    np.save(folder / "d3.npy", scans[2])
    (folder / "notes.txt").write_text("scanned on a Tuesday\n")
    kitti, tum = tmp_path / "poses.txt", tmp_path / "poses.tum"
    common = ["-o", str(tmp_path / "m.ply"), "--poses", str(tmp_path / "p.json")]
    status = main(["reconstruct", str(folder), *common, "--trajectory", str(kitti)])
    assert status == EXIT_UNRELIABLE
    summary = json.loads((tmp_path / "p.json").read_text())
    assert summary["unconnected"] == [str(folder / "b1.npy")]
    poses = read_poses(kitti, "kitti")
    assert len(poses) == 4 and poses[1] is None
    assert all(p is not None for k, p in enumerate(poses) if k != 1)
    np.testing.assert_array_equal(poses[0], np.eye(4))
    assert kitti.read_text().splitlines()[1] == " ".join(["nan"] * 12)
    pattern = str(folder / "[acd]*.npy")
    args = ["reconstruct", pattern, *common, "--trajectory", str(tum), "--trajectory-format", "tum"]
    assert main(args) == 0
    assert np.loadtxt(tum)[:, 0].tolist() == [0.0, 1.0, 2.0]
    capsys.readouterr()
    assert main(["reconstruct", str(tmp_path / "nothing*.ply"), *common]) == 1
    assert "no file matches this pattern" in capsys.readouterr().err


def test_reconstruct_reaches_every_setting_and_records_its_run(tmp_path, capsys):
    """--global, --voxel-size (the resolution, as register's), --min-fitness,
    --max-violation and a
    config's sections reach register_multiway: the poses equal the library's called
    with the same options; the poses file records the run, and ``config --from`` on it
    repeats the run to the bit. A refinement multiway cannot use is refused before any
    scan is read."""
    from o3d_rpointhop import register_multiway
    from o3d_rpointhop.cli import EXIT_OK
    from o3d_rpointhop.registration import RegistrationSettings
    from o3d_rpointhop.registration.steps import RANSACGlobal

    scans, _ = partial_views(3, seed=3)
    names = []
    for k, scan in enumerate(scans):
        np.save(tmp_path / f"s{k}.npy", scan)
        names.append(str(tmp_path / f"s{k}.npy"))
    poses = tmp_path / "p.json"
    args = [
        *names, "-o", str(tmp_path / "m.ply"), "--poses", str(poses), "--global", "ransac",
        "--voxel-size", "0.04", "--min-fitness", "0.4", "--max-violation", "0.2",
        "--set", "ransac.max_iteration=50000",
        "--set", "settings.edge_factor=2.0", "--n-jobs", "1",
    ]  # fmt: skip
    assert main(["reconstruct", *args]) == EXIT_OK
    summary = json.loads(poses.read_text())
    expected = register_multiway(
        scans,
        global_method=RANSACGlobal(max_iteration=50000),
        voxel_size=0.04,
        min_fitness=0.4,
        max_violation=0.2,
        settings=RegistrationSettings(edge_factor=2.0),
    )
    assert summary["voxel_size"] == 0.04
    for got, want in zip(summary["poses"], expected.poses, strict=True):
        np.testing.assert_array_equal(np.array(got), want)
    config = summary["provenance"]["config"]
    assert config["multiway"]["min_fitness"] == 0.4
    assert config["multiway"]["max_violation"] == 0.2
    assert config["ransac"]["max_iteration"] == 50000 and config["register"]["voxel_size"] == 0.04
    toml = tmp_path / "c.toml"
    assert main(["config", "--from", str(poses), "-o", str(toml)]) == 0
    again = tmp_path / "q.json"
    plain = [*names, "-o", str(tmp_path / "m2.ply"), "--poses", str(again), "--config", str(toml)]
    assert main(["reconstruct", *plain]) == EXIT_OK
    assert json.loads(again.read_text())["poses"] == summary["poses"]
    capsys.readouterr()
    status = main(
        [
            "reconstruct",
            "no.ply",
            "such.ply",
            "-o",
            "x.ply",
            "--set",
            "register.refine='generalized'",
        ]
    )
    assert status == 2 and "point_to_plane ICP only" in capsys.readouterr().err


def test_fit_then_describe(tmp_path, capsys):
    clouds = [
        write_points(tmp_path / f"c{i}.ply", make_object(300, shape_seed=i)) for i in range(3)
    ]
    model_path = tmp_path / "model.npz"
    assert main(["fit", *clouds, "-o", str(model_path), "--random-state", "0"]) == 0
    assert "3 clouds" in capsys.readouterr().out
    model = RPointHopTransformer.load(model_path)

    query = write_points(tmp_path / "q.pcd", make_object(250, shape_seed=9))
    out = tmp_path / "desc.npy"
    assert main(["describe", query, "--model", str(model_path), "-o", str(out)]) == 0
    desc = np.load(out)
    np.testing.assert_array_equal(desc, model.transform(read_cloud(query)))


def test_fit_passes_hop_parameters(tmp_path):
    clouds = [
        write_points(tmp_path / f"c{i}.npy", make_object(200, shape_seed=i)) for i in range(2)
    ]
    model_path = tmp_path / "m.npz"
    args = [
        "fit",
        *clouds,
        "-o",
        str(model_path),
        "--n-neighbors",
        "16,16",
        "--hop-sizes",
        "1.0,0.5",
        "--lrf-neighbors",
        "20",
        "--energy-threshold",
        "0.01",
    ]
    assert main(args) == 0
    model = RPointHopTransformer.load(model_path)
    assert model.n_neighbors == (16, 16) and model.hop_sizes == (1.0, 0.5)
    assert model.lrf_neighbors == 20 and model.energy_threshold == 0.01


def test_fit_the_scene_variant_with_axes_and_viewpoints(tmp_path):
    from o3d_rpointhop.evaluation.scene_models import SCENE_PARAMS

    clouds = [
        write_points(tmp_path / f"c{i}.npy", make_object(900, shape_seed=i) + [0, 0, 3.0])
        for i in range(2)
    ]
    out = tmp_path / "m.npz"
    common = ["fit", *clouds, "-o", str(out), "--lrf-neighbors", "32"]
    assert main([*common, "--scene", "--n-components", "8", "--viewpoints", "origin"]) == 0
    model = RPointHopTransformer.load(out)
    assert model.attributes == SCENE_PARAMS["attributes"] and model.n_neighbors == (96,)
    assert model.lrf_neighbors == 32 and model.n_features_out_ == 8  # options win
    expected = RPointHopTransformer(**{**SCENE_PARAMS, "lrf_neighbors": 32, "n_components": 8})
    expected.fit([read_cloud(c) for c in clouds], viewpoints="origin")
    cloud = read_cloud(clouds[0])
    np.testing.assert_array_equal(
        model.transform(cloud, viewpoints="origin"), expected.transform(cloud, viewpoints="origin")
    )
    assert main([*common, "--n-components", "none"]) == 0
    assert RPointHopTransformer.load(out).n_components is None


def test_demo_registers_the_synthetic_pair_and_draws_it(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["demo", "--synthetic", "--json", "--output-dir", str(out)]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["pair"].startswith("synthetic")
    assert summary["rotation_error_deg"] < 1.0 and summary["translation_error"] < 0.01
    png = (out / "before_after.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 20_000
    np.testing.assert_allclose(
        np.loadtxt(out / "transform.txt"), np.array(summary["transformation"]), atol=1e-7
    )
    assert len(read_cloud(out / "aligned.ply").points) == summary["source_points"]
    assert summary["no_picture"] is None and str(out / "before_after.png") in summary["outputs"]


def test_demo_without_matplotlib_registers_and_says_why_there_is_no_picture(
    tmp_path, capsys, monkeypatch
):
    import o3d_rpointhop.plotting as plotting

    def missing():
        raise ImportError("pictures need matplotlib: pip install '.[plot]' in the project folder")

    monkeypatch.setattr(plotting, "require_matplotlib", missing)
    assert main(["demo", "--synthetic", "--output-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "no picture: pictures need matplotlib: pip install '.[plot]'" in out
    assert (tmp_path / "transform.txt").is_file() and not (tmp_path / "before_after.png").exists()


def test_demo_on_your_own_pair(tmp_path, capsys):
    src, tgt, truth = moved_pair_files(tmp_path)
    assert (
        main(["demo", "--source", src, "--target", tgt, "--json", "--output-dir", str(tmp_path)])
        == 0
    )
    summary = json.loads(capsys.readouterr().out)
    assert "rotation_error_deg" not in summary  # no ground truth for a user's pair
    np.testing.assert_allclose(np.array(summary["transformation"]), truth, atol=1e-5)
    assert main(["demo", "--source", src]) == 1
    assert "both --source and --target" in capsys.readouterr().err


def test_register_writes_aligned_cloud_and_transforms(tmp_path, capsys):
    src, tgt, truth = moved_pair_files(tmp_path)
    out = tmp_path / "aligned.ply"
    code = main(
        [
            "register",
            src,
            tgt,
            "--refine",
            "point_to_plane",
            "-o",
            str(out),
            "--transform",
            str(tmp_path / "T.txt"),
            "--json",
        ]
    )
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(np.array(summary["transformation"]), truth, atol=1e-6)
    np.testing.assert_allclose(np.loadtxt(tmp_path / "T.txt"), truth, atol=1e-6)
    aligned = np.asarray(read_cloud(out).points)
    np.testing.assert_allclose(
        np.sort(aligned, axis=0), np.sort(np.asarray(read_cloud(tgt).points), axis=0), atol=1e-5
    )
    assert [s["name"] for s in summary["steps"]] == ["global", "refine"]

    assert main(["register", src, tgt, "--transform", str(tmp_path / "T.json")]) == 0
    text = capsys.readouterr().out
    assert "fitness" in text
    saved = json.loads((tmp_path / "T.json").read_text())
    np.testing.assert_allclose(np.array(saved["transformation"]), truth, atol=1e-6)


def test_register_options(tmp_path, capsys):
    src, tgt, truth = moved_pair_files(tmp_path)
    for extra in (
        ["--descriptor", "fpfh"],
        ["--descriptor", "rpointhop+fpfh"],
        ["--global", "svd", "--refine", "none"],
        ["--global", "fgr", "--refine", "multiscale", "--voxel-size", "0.04"],
        ["--refine", "point_to_point", "--symmetry-check"],
        ["--n-global-points", "500"],
    ):
        assert main(["register", src, tgt, "--json", *extra]) == 0, extra
        result = json.loads(capsys.readouterr().out)
        assert ("symmetry_check" in [s["name"] for s in result["steps"]]) == (
            "--symmetry-check" in extra
        )
        estimate = np.array(result["transformation"])
        assert np.abs(estimate - truth).max() < 0.02, extra
    init = tmp_path / "init.txt"
    np.savetxt(init, truth)
    assert main(["register", src, tgt, "--global", "none", "--init", str(init), "--json"]) == 0
    assert (
        np.abs(np.array(json.loads(capsys.readouterr().out)["transformation"]) - truth).max() < 1e-6
    )


def test_register_with_rpointhop_and_fpfh_records_the_union(tmp_path, capsys):
    src, tgt, truth = moved_pair_files(tmp_path)
    args = ["register", src, tgt, "--descriptor", "rpointhop+fpfh", "--model", "scene"]
    assert main([*args, "--set", "descriptor.fpfh_weight=1.5", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    record = summary["provenance"]
    union = record["descriptor"]
    assert union["class"] == "o3d_rpointhop.DescriptorUnion"
    assert union["parts"]["rpointhop"]["model"] == "scene"
    assert union["parts"]["fpfh"]["class"] == "o3d_rpointhop.FPFHTransformer"
    assert union["transformer_weights"] == {"fpfh": 1.5}
    assert record["config"]["descriptor"]["fpfh_weight"] == 1.5
    assert np.abs(np.array(summary["transformation"]) - truth).max() < 0.02


def test_demo_prints_a_human_summary_and_says_when_it_falls_back(tmp_path, capsys):
    missing = tmp_path / "no-data-here"
    missing.mkdir()
    assert main(["demo", "--data", str(missing), "--output-dir", str(tmp_path / "o")]) == 0
    text = capsys.readouterr().out
    assert text.startswith("No real data found, so the demo uses a synthetic object")
    assert "rotation error" in text and "fitness" in text and "before_after.png" in text
    assert "{" not in text  # not JSON


def test_shipped_models_by_name(tmp_path):
    query = write_points(tmp_path / "q.ply", make_object(600, shape_seed=9))
    out = tmp_path / "scene.npy"
    assert (
        main(["describe", query, "--model", "scene", "--n-components", "16", "-o", str(out)]) == 0
    )
    expected = RPointHopTransformer.pretrained("scene", n_components=16).transform(
        read_cloud(query)
    )
    np.testing.assert_array_equal(np.load(out), expected)
    assert main(["describe", query, "--model", "modelnet40", "-o", str(out)]) == 0
    assert np.load(out).shape == (600, 1624)


def test_evaluate_at_survey_coordinates_reports_the_data_s_error(tmp_path, capsys):
    """A pair at a UTM-like offset whose estimate is off by a 2e-6 rad turn about the
    source's centroid: every source point moves by at most 2e-6 of its distance from the
    centroid (a fraction of a millimetre), while the translations themselves differ by
    about 2e-6 of the 6e6 m offset, metres."""

    offset = np.array([500_000.0, 6_000_000.0, 120.0])
    cloud = make_object(800, shape_seed=2) * 40.0 + offset  # a 40 m object at UTM
    np.save(tmp_path / "s.npy", cloud)
    np.save(tmp_path / "t.npy", cloud)
    truth = np.eye(4)
    angle = 2e-6
    turn = np.array(
        [[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]]
    )
    centre = cloud.mean(axis=0)
    estimate = np.eye(4)
    estimate[:3, :3], estimate[:3, 3] = turn, centre - turn @ centre
    np.savetxt(tmp_path / "T.txt", estimate, fmt="%.17g")
    np.savetxt(tmp_path / "G.txt", truth, fmt="%.17g")
    files = [str(tmp_path / "s.npy"), str(tmp_path / "t.npy")]
    code = main(
        [
            "evaluate",
            *files,
            "--transform",
            str(tmp_path / "T.txt"),
            "--truth",
            str(tmp_path / "G.txt"),
            "--json",
        ]
    )
    assert code in (0, 3)
    summary = json.loads(capsys.readouterr().out)
    spread = np.linalg.norm(cloud - centre, axis=1)
    expected_rms = angle * np.sqrt(np.mean(np.sum((cloud - centre)[:, :2] ** 2, axis=1)))
    # arccos of a trace near 3 keeps about 1e-8 rad: the angle to a per cent
    assert summary["rotation_error_deg"] == pytest.approx(np.degrees(angle), rel=2e-2)
    assert summary["translation_error"] < 1e-6  # the centroid is where the turn pivots
    assert summary["rms_displacement"] == pytest.approx(expected_rms, rel=1e-3)
    assert summary["rms_displacement"] < angle * spread.max() < 1e-3
    assert np.linalg.norm(estimate[:3, 3] - truth[:3, 3]) > 10.0  # what the origin would say


def test_register_takes_sensor_positions_and_an_up_axis(tmp_path, capsys):
    """--viewpoints as one position per cloud (each in its own coordinates) and --up as
    a direction reach register(): the same estimate as the library's with them."""
    from o3d_rpointhop import register

    src, tgt, truth = moved_pair_files(tmp_path)
    views = "0,0,3;0.2,-0.1,3.3"
    assert main(["register", src, tgt, "--json", "--viewpoints", views, "--up", "0,0,1"]) == 0
    result = json.loads(capsys.readouterr().out)
    estimate = np.array(result["transformation"])
    assert np.abs(estimate - truth).max() < 0.02
    library = register(
        read_cloud(src),
        read_cloud(tgt),
        viewpoints=([0, 0, 3.0], [0.2, -0.1, 3.3]),
        up=[0, 0, 1.0],
    )
    np.testing.assert_allclose(estimate, library.transformation, atol=1e-9)
    for option, value in (("--viewpoints", "0,0;1,1,1"), ("--up", "0,0"), ("--up", "x,y,z")):
        with pytest.raises(SystemExit) as exc:
            main(["register", src, tgt, option, value])
        assert exc.value.code == 2
        assert "expected" in capsys.readouterr().err


def test_register_exits_3_and_says_so_when_the_result_is_ambiguous(tmp_path, capsys):
    """A box and the same box sampled again: its half-turn fits as well, so the command
    exits 3 with the warning, and the JSON says ambiguous."""
    from o3d_rpointhop.cli import EXIT_UNRELIABLE
    from o3d_rpointhop.datasets.synthetic import _box_surface

    rng = np.random.default_rng(0)
    half = np.array([1.0, 0.5, 0.25])
    src = write_points(tmp_path / "a.ply", _box_surface(rng, 1500, half))
    tgt = write_points(tmp_path / "b.ply", _box_surface(rng, 1500, half))
    assert main(["register", src, tgt, "--json"]) == EXIT_UNRELIABLE
    captured = capsys.readouterr()
    assert json.loads(captured.out)["ambiguous"] is True
    assert "ambiguous" in captured.err


def test_folders_and_patterns_list_scans_in_natural_order(tmp_path):
    """cloud_bin_3 before cloud_bin_23 and scan_9 before scan_10, in a folder and in a
    pattern, as a person numbering files means them (by name, 23 came first)."""
    from o3d_rpointhop.cli._paths import scan_paths

    names = ["cloud_bin_23.npy", "cloud_bin_3.npy", "cloud_bin_10.npy", "Cloud_bin_4.npy"]
    for name in names:
        np.save(tmp_path / name, np.zeros((1, 3)))
    (tmp_path / "notes.txt").write_text("not a scan")
    want = ["cloud_bin_3.npy", "Cloud_bin_4.npy", "cloud_bin_10.npy", "cloud_bin_23.npy"]
    assert [Path(p).name for p in scan_paths([str(tmp_path)])] == want
    assert [Path(p).name for p in scan_paths([str(tmp_path / "*.npy")])] == want
    other = tmp_path / "scans"
    other.mkdir()
    for k in (10, 9, 100):
        np.save(other / f"scan_{k}.npy", np.zeros((1, 3)))
    assert [Path(p).name for p in scan_paths([str(other)])] == [
        "scan_9.npy",
        "scan_10.npy",
        "scan_100.npy",
    ]


@pytest.mark.slow
def test_reconstruct_sequential_reaches_register_multiway(tmp_path, monkeypatch):
    """--sequential says the scans come in acquisition order; without it the order of
    the files does not matter (register_multiway's default)."""
    from o3d_rpointhop import registration
    from o3d_rpointhop.cli import EXIT_OK

    real, seen = registration.register_multiway, []

    def spy(*args, **kwargs):
        seen.append(kwargs.get("sequential"))
        return real(*args, **kwargs)

    monkeypatch.setattr(registration, "register_multiway", spy)
    scans, _ = partial_views(3, seed=3)
    names = []
    for k, scan in enumerate(scans):
        np.save(tmp_path / f"s{k}.npy", scan)
        names.append(str(tmp_path / f"s{k}.npy"))
    out = ["-o", str(tmp_path / "m.ply"), "--n-jobs", "1"]
    assert main(["reconstruct", *names, *out]) == EXIT_OK
    assert main(["reconstruct", *names, *out, "--sequential", "--force"]) == EXIT_OK
    assert seen == [False, True]
