"""The bunny benchmark's dragon protocol on a small synthetic scan set laid out as the
Stanford dragon's folder: which scans pair with which, the truth from the ``.conf``, and
which protocols run when none is named."""

from __future__ import annotations

import open3d as o3d
import pytest
from scipy.spatial.transform import Rotation

from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.evaluation.bunny import DRAGON_TARGET, default_protocols, run_bunny


def _write_dragon(folder, angles=(0, 24, 336)):
    """One and the same 10 cm scan under every name of ``angles``, with a
    ``dragonStandRight.conf`` that puts each turned by its angle (degrees) about the
    vertical axis: the truth of a pair is then the turn between the two, and ICP from
    the identity, which the identical scans hold, misses it by exactly that."""
    folder.mkdir(parents=True)
    scan = make_object(3000, shape_seed=5, sample_seed=1) * 0.1
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(scan))
    lines = ["camera 0 -0.1 -0.7 0 1 0 0"]
    for angle in angles:
        o3d.io.write_point_cloud(str(folder / f"dragonStandRight_{angle}.ply"), cloud)
        q = Rotation.from_euler("y", angle, degrees=True).as_quat()
        shift = [0.001, 0.0, -0.002]
        lines.append(f"bmesh dragonStandRight_{angle}.ply {' '.join(map(str, [*shift, *q]))}")
    (folder / "dragonStandRight.conf").write_text("\n".join(lines) + "\n")


def test_dragon_protocol_registers_every_scan_to_the_first(tmp_path):
    _write_dragon(tmp_path / "stanford" / "dragon_stand")
    results = run_bunny(["dragon"], ["icp"], data=tmp_path, progress=False)
    dragon = results["protocols"]["dragon"]
    records = dragon["records"]["icp"]
    assert [r["pair"] for r in records] == ["dragonStandRight_24", "dragonStandRight_336"]
    assert dragon["success"] == "rotation error < 2.0 deg and translation error < 2.0 mm"
    # The truth is the conf's turn from each scan to dragonStandRight_0: 24 deg both.
    assert [r["rotation_error_deg"] for r in records] == pytest.approx([24.0, 24.0], abs=1e-3)
    assert dragon["summary"]["icp"]["success_rate"] == 0.0
    assert set(dragon["overlap"]) == {"dragonStandRight_24", "dragonStandRight_336"}
    assert all(0.0 < v < 1.0 for v in dragon["overlap"].values())
    assert "scans" not in results["protocols"] and "paper" not in results["protocols"]


def test_dragon_protocol_says_which_scan_is_missing(tmp_path):
    _write_dragon(tmp_path / "stanford" / "dragon_stand", angles=(24, 48))
    with pytest.raises(FileNotFoundError, match=DRAGON_TARGET):
        run_bunny(["dragon"], ["icp"], data=tmp_path, progress=False)


def test_unknown_protocol_is_refused_before_any_data_is_read(tmp_path):
    with pytest.raises(ValueError, match="unknown bunny protocol 'nowhere'"):
        run_bunny(["nowhere"], ["icp"], data=tmp_path, progress=False)


def test_the_dragon_runs_by_default_only_where_its_scans_are(tmp_path):
    assert default_protocols(tmp_path) == ["scans", "paper"]
    _write_dragon(tmp_path / "stanford" / "dragon_stand")
    assert default_protocols(tmp_path) == ["scans", "paper", "dragon"]
