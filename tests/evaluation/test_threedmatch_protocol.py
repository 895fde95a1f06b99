"""The official 3DMatch protocol on a tiny synthetic benchmark folder: the pair filter, the
scene mean beside the pair mean, the RE / TE criterion, precision over claimed results,
every estimate kept, and the viewpoints passed to the methods."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import motion_matrix
from scipy.spatial.transform import Rotation

from o3d_rpointhop.datasets import load_3dmatch_pairs, make_room
from o3d_rpointhop.evaluation.records import ScenePairRecord
from o3d_rpointhop.evaluation.threedmatch import official_pairs, run_3dmatch, summarize_3dmatch
from o3d_rpointhop.io import write_cloud
from o3d_rpointhop.transforms import apply_transform

# Scene -> fragment ids; pairs (i, j) listed in gt.log.
SCENES = {"scene-a": (0, 1, 3), "scene-b": (0, 2)}
PAIRS = {"scene-a": [(0, 1), (0, 3), (1, 3)], "scene-b": [(0, 2)]}


def _pose(k: int) -> np.ndarray:
    """Fragment k's pose in its scene (maps fragment points into the scene)."""
    rot = Rotation.from_rotvec([0.0, 0.0, 0.3 * k]).as_matrix()
    return motion_matrix(rot, [0.2 * k, -0.1 * k, 0.05])


def _write_records(path, records: dict, size: int) -> None:
    lines = []
    for (i, j), matrix in records.items():
        lines.append(f"{i} {j} 60")
        lines += [" ".join(f"{v:.12f}" for v in row) for row in matrix.reshape(size, size)]
    path.write_text("\n".join(lines) + "\n")


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    root = tmp_path_factory.mktemp("threedmatch") / "3dmatch"
    for scene, frags in SCENES.items():
        (root / "fragments" / scene).mkdir(parents=True)
        room = make_room(2500, random_state=len(scene))
        for k in frags:
            # Each fragment in its own frame (its sensor at its origin).
            points = apply_transform(room, np.linalg.inv(_pose(k)))
            write_cloud(root / "fragments" / scene / f"cloud_bin_{k}.ply", points)
        gt = root / "benchmarks" / "3DMatch" / scene
        gt.mkdir(parents=True)
        log = {(i, j): np.linalg.inv(_pose(i)) @ _pose(j) for i, j in PAIRS[scene]}
        _write_records(gt / "gt.log", log, 4)
        _write_records(gt / "gt.info", {p: np.eye(6) * 4.0 for p in PAIRS[scene]}, 6)
        (gt / "gt_overlap.log").write_text(
            "\n".join(f"{i},{j},0.6" for i, j in PAIRS[scene]) + "\n"
        )
    return root


def test_the_official_pairs_leave_consecutive_fragments_out(folder):
    pairs = load_3dmatch_pairs(folder)
    assert [(p.scene, p.i, p.j) for p in pairs] == [
        ("scene-a", 0, 1),
        ("scene-a", 0, 3),
        ("scene-a", 1, 3),
        ("scene-b", 0, 2),
    ]
    kept = official_pairs(pairs)
    assert [(p.scene, p.i, p.j) for p in kept] == [
        ("scene-a", 0, 3),
        ("scene-a", 1, 3),
        ("scene-b", 0, 2),
    ]
    assert all(p.information[0, 0] == 4.0 and p.overlap == 0.6 for p in kept)


@pytest.mark.slow
def test_a_run_keeps_every_estimate_and_reports_the_official_summary(folder):
    results = run_3dmatch(["icp", "fpfh-pipeline-consensus-icp"], data=folder, progress=False)
    assert results["settings"]["protocol"].startswith("official")
    assert results["settings"]["viewpoints"] == "origin"
    protocol = results["protocols"]["3DMatch"]
    assert "3DLoMatch" not in results["protocols"]  # no pairs there
    records = protocol["records"]["fpfh-pipeline-consensus-icp"]
    assert [r["pair"] for r in records] == ["scene-a 0-3", "scene-a 1-3", "scene-b 0-2"]
    for rec, pair in zip(records, official_pairs(load_3dmatch_pairs(folder)), strict=True):
        estimate = np.array(rec["transformation"])
        assert estimate.shape == (4, 4)
        # The kept estimate is the one the record was scored on.
        error = np.linalg.norm(estimate[:3, 3] - pair.truth[:3, 3])
        assert (error < 0.05) == rec["registered"]
        assert isinstance(rec["claimed"], bool)
    assert protocol["records"]["icp"][0]["claimed"] is None  # ICP alone claims nothing
    summary = protocol["summary"]["fpfh-pipeline-consensus-icp"]
    assert summary["pairs"] == 3 and summary["scenes"] == 2
    assert summary["precision"] is not None
    assert protocol["summary"]["icp"]["precision"] is None
    assert set(protocol["diagnostics"]) == {"fpfh"}
    everything = run_3dmatch(["icp"], data=folder, official=False, progress=False)
    assert everything["protocols"]["3DMatch"]["summary"]["icp"]["pairs"] == 4
    with pytest.raises(ValueError, match="viewpoints must be one of"):
        run_3dmatch(["icp"], data=folder, viewpoints="camera", progress=False)


def _rec(scene, registered, re_te=None, claimed=None):
    return ScenePairRecord(
        pair="p",
        scene=scene,
        overlap=None,
        rmse=0.1 if registered else 1.0,
        registered=registered,
        registered_re_te=registered if re_te is None else re_te,
        claimed=claimed,
        seconds=1.0,
        rotation_error_deg=1.0 if registered else 90.0,
        translation_error=0.01 if registered else 1.0,
        transformation=np.eye(4).tolist(),
    )


def test_the_summary_averages_scenes_then_pairs_and_counts_claims():
    """Scene a: 3 of 4 registered; scene b: 0 of 1. Recall over scenes (0.75 + 0) / 2,
    over pairs 3 / 5. The method claims 4 results, 3 of them right: precision 3 / 4."""
    ours = [
        _rec("a", True, claimed=True),
        _rec("a", True, claimed=True),
        _rec("a", True, re_te=False, claimed=True),
        _rec("a", False, claimed=False),
        _rec("b", False, claimed=True),
    ]
    theirs = [_rec("a", r.registered or k == 3) for k, r in enumerate(ours)]
    out = summarize_3dmatch({"ours": ours, "theirs": theirs})
    summary = out["summary"]["ours"]
    assert summary["registration_recall"] == pytest.approx(0.375)
    assert summary["registration_recall_pairs"] == pytest.approx(0.6)
    assert summary["recall_re_te"] == pytest.approx((2 / 4 + 0) / 2)
    assert summary["precision"] == pytest.approx(0.75) and summary["claimed"] == 4
    assert out["summary"]["theirs"]["precision"] is None
    assert out["per_scene"]["ours"]["a"] == {
        "pairs": 4,
        "registration_recall": 0.75,
        "recall_re_te": 0.5,
    }
    assert out["paired"]["ours vs theirs"]["b_only"] == 1
    assert out["paired"]["ours vs theirs"]["a_only"] == 0
