"""The o3d-rpointhop command line."""

from __future__ import annotations

import json

import numpy as np
import open3d as o3d
import pytest

from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.cli import main
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.io import read_cloud, write_cloud


def _write(path, points):
    write_cloud(path, points)
    return str(path)


def test_fit_then_describe(tmp_path, capsys):
    clouds = [_write(tmp_path / f"c{i}.ply", make_object(300, shape_seed=i)) for i in range(3)]
    model_path = tmp_path / "model.npz"
    assert main(["fit", *clouds, "-o", str(model_path), "--random-state", "0"]) == 0
    assert "3 clouds" in capsys.readouterr().out
    model = RPointHopTransformer.load(model_path)

    query = _write(tmp_path / "q.pcd", make_object(250, shape_seed=9))
    out = tmp_path / "desc.npy"
    assert main(["describe", query, "--model", str(model_path), "-o", str(out)]) == 0
    desc = np.load(out)
    np.testing.assert_array_equal(desc, model.transform(read_cloud(query)))


def test_fit_passes_hop_parameters(tmp_path):
    clouds = [_write(tmp_path / f"c{i}.npy", make_object(200, shape_seed=i)) for i in range(2)]
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


def test_demo_on_your_own_pair(tmp_path, capsys):
    src, tgt, truth = _pair(tmp_path)
    assert (
        main(["demo", "--source", src, "--target", tgt, "--json", "--output-dir", str(tmp_path)])
        == 0
    )
    summary = json.loads(capsys.readouterr().out)
    assert "rotation_error_deg" not in summary  # no ground truth for a user's pair
    np.testing.assert_allclose(np.array(summary["transformation"]), truth, atol=1e-5)
    assert main(["demo", "--source", src]) == 1
    assert "both --source and --target" in capsys.readouterr().err


@pytest.mark.parametrize(
    "args, message",
    [
        (["describe", "missing.ply", "--model", "m.npz", "-o", "d.npy"], "no such file"),
        (["fit", "bad.ply", "-o", "m.npz"], "bad.ply: damaged or unreadable .ply file (RPly:"),
        (["fit", "cloud.foo", "-o", "m.npz"], "unknown point cloud format"),
        (["fit", "small.npy", "-o", "m.npz"], "too few"),
    ],
)
def test_bad_input_exits_nonzero_with_a_message(tmp_path, monkeypatch, capsys, args, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "bad.ply").write_text("not a ply file")
    (tmp_path / "cloud.foo").write_text("1 2 3")
    np.save(tmp_path / "small.npy", make_object(20))
    assert main(args) == 1
    err = capsys.readouterr().err
    assert err.startswith("o3d-rpointhop: error:") and message in err


def test_usage_errors_exit_2(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["fit"])
    assert exc.value.code == 2


def test_read_cloud_formats(tmp_path):
    pts = make_object(100, shape_seed=3)
    for name in ("a.ply", "a.pcd", "a.xyz", "a.npy"):
        _write(tmp_path / name, pts)
        np.testing.assert_allclose(np.asarray(read_cloud(tmp_path / name).points), pts, atol=1e-6)
    np.savetxt(tmp_path / "a.csv", np.c_[pts, np.ones(100)], delimiter=",")
    np.testing.assert_allclose(np.asarray(read_cloud(tmp_path / "a.csv").points), pts)
    np.savez(tmp_path / "a.npz", points=pts)
    np.testing.assert_allclose(np.asarray(read_cloud(tmp_path / "a.npz").points), pts)
    bad = pts.copy()
    bad[5, 1] = np.nan
    np.save(tmp_path / "nan.npy", bad)
    with pytest.raises(ValueError, match="NaN"):
        read_cloud(tmp_path / "nan.npy")
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    pcd.estimate_normals()
    write_cloud(tmp_path / "n.ply", pcd)
    assert read_cloud(tmp_path / "n.ply").has_normals()


# ----------------------------------------------------------------------------- register
def _pair(tmp_path):
    from scipy.spatial.transform import Rotation

    target = make_object(700, shape_seed=31)
    rot = Rotation.random(random_state=2).as_matrix()
    source = target @ rot.T + [0.2, -0.1, 0.3]
    truth = np.eye(4)
    truth[:3, :3] = rot.T
    truth[:3, 3] = -rot.T @ [0.2, -0.1, 0.3]
    return _write(tmp_path / "src.ply", source), _write(tmp_path / "tgt.pcd", target), truth


def test_register_writes_aligned_cloud_and_transforms(tmp_path, capsys):
    src, tgt, truth = _pair(tmp_path)
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
    src, tgt, truth = _pair(tmp_path)
    for extra in (
        ["--descriptor", "fpfh"],
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


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--descriptor", "fpfh", "--model", "m.npz"], "--model applies to the rpointhop"),
        (["--init", "bad.txt"], "not 4x4"),
        (["--model", "missing.npz"], "no such model file"),
        (["--refine", "none", "--symmetry-check"], "--symmetry-check needs an ICP"),
    ],
)
def test_register_errors(tmp_path, monkeypatch, capsys, extra, message):
    src, tgt, _ = _pair(tmp_path)
    monkeypatch.chdir(tmp_path)
    np.savetxt(tmp_path / "bad.txt", np.eye(3))
    assert main(["register", src, tgt, *extra]) == 1
    assert message in capsys.readouterr().err


def test_register_usage_errors():
    for args in (
        ["register", "a.ply"],
        ["register", "a", "b", "--voxel-size", "-1"],
        ["register", "a", "b", "--global", "teaser"],
        ["register", "a", "b", "--n-global-points", "2"],
        ["register", "a", "b", "--n-global-points", "many"],
    ):
        with pytest.raises(SystemExit) as exc:
            main(args)
        assert exc.value.code == 2


def test_demo_prints_a_human_summary_and_says_when_it_falls_back(tmp_path, capsys):
    missing = tmp_path / "no-data-here"
    missing.mkdir()
    assert main(["demo", "--data", str(missing), "--output-dir", str(tmp_path / "o")]) == 0
    text = capsys.readouterr().out
    assert text.startswith("No real data found, so the demo uses a synthetic object")
    assert "rotation error" in text and "fitness" in text and "before_after.png" in text
    assert "{" not in text  # not JSON


def test_shipped_models_by_name(tmp_path):
    query = _write(tmp_path / "q.ply", make_object(600, shape_seed=9))
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
