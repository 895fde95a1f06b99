"""Benchmark protocols, metrics and the benchmark command."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.evaluation.methods import METHODS, run_method
from o3d_rpointhop.evaluation.metrics import (
    is_symmetry,
    match_inlier_ratio,
    pair_errors,
    rmse_3dmatch,
    summarize,
)
from o3d_rpointhop.evaluation.protocols import PROTOCOLS, crop_nearest, make_pairs
from o3d_rpointhop.transforms import apply_transform


@pytest.fixture(scope="module")
def shapes():
    return np.stack([make_object(2048, shape_seed=s) for s in range(3)])


@pytest.mark.parametrize("protocol", sorted(PROTOCOLS))
def test_protocol_truth_maps_source_onto_its_clean_points(shapes, protocol):
    pairs = make_pairs(shapes, protocol, seed=0)
    assert len(pairs) == 3
    for pair, shape in zip(pairs, shapes, strict=True):
        back = apply_transform(pair.source, pair.truth)
        tol = 0.05 * np.sqrt(3) + 1e-9 if protocol.endswith("noise") else 1e-9
        assert np.abs(back - pair.source_clean).max() <= tol
        # the clean source points are points of the shape
        assert np.isin(
            pair.source_clean.view([("", float)] * 3), shape.view([("", float)] * 3)
        ).all()
        frac = {"paper-partial": 0.75, "resampled-partial": 0.70}.get(protocol, 1.0)
        assert len(pair.source) == round(frac * 1024) and len(pair.target) == round(frac * 1024)
        angles = np.degrees(np.arccos(np.clip((np.trace(pair.truth[:3, :3]) - 1) / 2, -1, 1)))
        if protocol.startswith("paper"):
            assert angles <= 45 * np.sqrt(3) + 1e-6
        if protocol.startswith("resampled"):
            overlap = set(map(tuple, pair.source_clean)) & set(map(tuple, pair.target))
            assert not overlap  # different samples: no shared points


def test_pairs_are_seeded(shapes):
    a = make_pairs(shapes, "resampled-noise", seed=4)
    b = make_pairs(shapes, "resampled-noise", seed=4)
    c = make_pairs(shapes, "resampled-noise", seed=5)
    np.testing.assert_array_equal(a[1].source, b[1].source)
    assert not np.array_equal(a[1].source, c[1].source)
    with pytest.raises(ValueError, match="unknown protocol"):
        make_pairs(shapes, "upside-down")


def test_crop_keeps_the_points_nearest_to_one_point():
    pts = np.random.default_rng(0).normal(size=(200, 3))
    keep = crop_nearest(pts, 0.25, np.random.default_rng(1))
    assert len(keep) == 50
    centre = pts[np.random.default_rng(1).integers(200)]  # the crop's random centre
    rest = np.setdiff1d(np.arange(200), keep)
    kept_far = np.linalg.norm(pts[keep] - centre, axis=1).max()
    assert kept_far <= np.linalg.norm(pts[rest] - centre, axis=1).min()


def test_errors_and_summary():
    truth = np.eye(4)
    est = np.eye(4)
    est[:3, :3] = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])  # 90 deg about z
    est[:3, 3] = [0.1, 0, 0]
    e = pair_errors(est, truth)
    assert e["rotation_error_deg"] == pytest.approx(90)
    assert e["translation_error"] == pytest.approx(0.1)
    assert sorted(np.abs(e["euler_error_deg"])) == pytest.approx([0, 0, 90])
    good = {**pair_errors(np.eye(4), truth), "seconds": 1.0, "symmetric": False}
    s = summarize([good, {**e, "seconds": 3.0, "symmetric": True}])
    assert s["success_rate"] == 0.5 and s["success_rate_up_to_symmetry"] == 1.0
    assert s["mae_r"] == pytest.approx(15.0) and s["seconds_per_pair"] == 2.0
    assert s["mae_r_not_symmetric"] == pytest.approx(0.0)  # the flip is left out
    assert s["rmse_r"] == pytest.approx(np.sqrt(90**2 / 6))


def test_symmetry_check():
    rng = np.random.default_rng(0)
    phi = rng.uniform(0, 2 * np.pi, 4000)
    z = rng.uniform(-1, 1, 4000)
    cylinder = np.c_[np.cos(phi), np.sin(phi), z]  # symmetric about z
    turn = np.eye(4)
    turn[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    assert is_symmetry(turn, np.eye(4), cylinder)
    tilt = np.eye(4)
    tilt[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
    assert not is_symmetry(tilt, np.eye(4), cylinder)


def test_every_method_runs(shapes):
    from o3d_rpointhop import RPointHopTransformer

    model = RPointHopTransformer().fit(list(shapes[:, :1024]))
    (pair,) = make_pairs(shapes[:1], "paper", seed=0)
    for name in METHODS:
        estimate, seconds = run_method(name, pair.source, pair.target, descriptor=model, voxel=0.05)
        rotation = estimate[:3, :3]
        assert estimate.shape == (4, 4) and np.isfinite(seconds)
        np.testing.assert_allclose(rotation.T @ rotation, np.eye(3), atol=1e-9)  # rigid
        assert np.linalg.det(rotation) == pytest.approx(1.0) and estimate[3].tolist() == [
            0,
            0,
            0,
            1,
        ]
        if name != "icp":  # a moved copy: every global method must find it
            assert pair_errors(estimate, pair.truth)["rotation_error_deg"] < 2.0, name
    with pytest.raises(ValueError, match="unknown method"):
        run_method("magic", pair.source, pair.target, descriptor=model, voxel=0.05)


@pytest.mark.realdata
def test_benchmark_command_writes_json_markdown_and_plots(shared_data, tmp_path, capsys):
    from o3d_rpointhop.cli import main

    args = [
        "benchmark",
        "modelnet40",
        "--data",
        str(shared_data),
        "--output",
        str(tmp_path),
        "--max-shapes",
        "2",
        "--protocol",
        "paper",
        "resampled",
        "angle-sweep",
        "--methods",
        "rpointhop-ransac-icp,icp",
        "--no-progress",
    ]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "## resampled" in out and "R-PointHop + RANSAC + point-to-plane ICP" in out
    results = json.loads((tmp_path / "modelnet40.json").read_text())
    paper = results["protocols"]["paper"]["summary"]
    assert paper["rpointhop-ransac-icp"]["success_rate"] == 1.0
    assert set(results["protocols"]["angle-sweep"]["summary"]) == {
        "0",
        "15",
        "30",
        "45",
        "60",
        "90",
        "120",
        "150",
        "180",
    }
    assert (tmp_path / "modelnet40_success_rate.png").stat().st_size > 1000
    assert (tmp_path / "modelnet40_angle-sweep.png").stat().st_size > 1000
    # repeatable: the same seed gives the same numbers
    main(args)
    again = json.loads((tmp_path / "modelnet40.json").read_text())
    for method in ("rpointhop-ransac-icp", "icp"):
        first = results["protocols"]["resampled"]["records"][method]
        second = again["protocols"]["resampled"]["records"][method]
        assert [r["rotation_error_deg"] for r in first] == [r["rotation_error_deg"] for r in second]


def test_benchmark_command_rejects_bad_choices(capsys):
    from o3d_rpointhop.cli import main

    assert main(["benchmark", "3dmatch", "--protocol", "x"]) == 1
    assert "no protocols" in capsys.readouterr().err


def test_modelnet40_loader_reads_the_official_h5_layout(tmp_path):
    h5py = pytest.importorskip("h5py")
    from o3d_rpointhop.datasets import load_modelnet40

    rng = np.random.default_rng(0)
    shapes = [rng.normal(size=(3, 2048, 3)).astype(np.float32) for _ in range(2)]
    for k, data in enumerate(shapes):
        with h5py.File(tmp_path / f"ply_data_test{k}.h5", "w") as h5:
            h5["data"] = data
            h5["label"] = np.arange(3, dtype=np.uint8)[:, None] + k
    (tmp_path / "shape_names.txt").write_text("\n".join(f"class{i}" for i in range(40)))
    test = load_modelnet40("test", tmp_path)
    assert test.points.shape == (6, 2048, 3) and test.labels.tolist() == [0, 1, 2, 1, 2, 3]
    assert test.class_names[3] == "class3"
    np.testing.assert_allclose(np.linalg.norm(test.points, axis=2).max(axis=1), 1.0)
    raw = load_modelnet40("test", tmp_path, normalize=False)
    np.testing.assert_allclose(raw.points[:3], shapes[0], rtol=1e-6)
    with pytest.raises(FileNotFoundError, match="no ModelNet40 train data"):
        load_modelnet40("train", tmp_path)


def test_3dmatch_error_and_match_inlier_ratio():
    from scipy.spatial.transform import Rotation

    from o3d_rpointhop import FPFHTransformer
    from o3d_rpointhop.registration.context import RegistrationContext

    truth = np.eye(4)
    truth[:3, :3] = Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix()
    truth[:3, 3] = [0.5, 0.1, -0.2]
    info = np.diag([2.0, 2.0, 2.0, 1.0, 1.0, 1.0])
    assert rmse_3dmatch(truth, truth, info) == pytest.approx(0.0, abs=1e-12)
    shifted = truth @ np.array([[1, 0, 0, 0.3], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])
    assert rmse_3dmatch(shifted, truth, info) == pytest.approx(0.3)  # sqrt(2 * 0.09 / 2)

    target = make_object(800, shape_seed=3)
    source = apply_transform(target, np.linalg.inv(truth))  # truth maps source to target
    context = RegistrationContext(source, target)
    fpfh = FPFHTransformer(radius="auto", normal_radius="auto")
    assert match_inlier_ratio(context, fpfh, truth) > 0.5
    assert match_inlier_ratio(context, fpfh, shifted, radius=0.1) == 0.0


def _fake_results(seconds: float) -> dict:
    records = [
        {**pair_errors(np.eye(4), np.eye(4)), "seconds": seconds, "pair": "a"},
        {**pair_errors(np.eye(4), np.eye(4)), "seconds": 2 * seconds, "pair": "b"},
    ]
    return {
        "dataset": "bunny",
        "settings": {
            "seed": 0,
            "machine": f"box {seconds}",
            "python": "3.11",
            "open3d": "0.20",
            "numpy": "2",
        },
        "protocols": {
            "scans": {
                "description": "two pairs",
                "summary": {"icp": summarize(records)},
                "records": {"icp": records},
                "fit_seconds": 10 * seconds,
            }
        },
    }


def test_reports_keep_timings_apart(tmp_path):
    from o3d_rpointhop.evaluation.report import split_timings, write_report

    kept, timed = split_timings(_fake_results(1.0))
    assert "seconds" not in json.dumps(kept) and "box" not in json.dumps(kept)
    assert timed["protocols"]["scans"]["records"]["icp"] == [{"seconds": 1.0}, {"seconds": 2.0}]
    assert timed["protocols"]["scans"]["summary"]["icp"] == {"seconds_per_pair": 1.5}
    first = write_report(_fake_results(1.0), tmp_path / "one")
    second = write_report(_fake_results(3.0), tmp_path / "two")
    names = [Path(p).name for p in first]
    assert names[:4] == ["bunny.json", "bunny.md", "bunny_timings.json", "bunny_timings.md"]
    for name in ("bunny.json", "bunny.md"):  # a rerun leaves the result files unchanged
        assert (tmp_path / "one" / name).read_text() == (tmp_path / "two" / name).read_text()
    assert "s per pair" not in (tmp_path / "one" / "bunny.md").read_text()
    assert (
        "| scans | point-to-point ICP alone" in (tmp_path / "two" / "bunny_timings.md").read_text()
    )
    assert "4.500" in (tmp_path / "two" / "bunny_timings.md").read_text()
    timings = json.loads((tmp_path / "two" / "bunny_timings.json").read_text())
    assert timings["settings"] == {"machine": "box 3.0"}
    assert [Path(p).name for p in second] == names
