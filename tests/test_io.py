"""Reading and writing point clouds in every format."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest
from helpers import write_points

from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.io import read_cloud, write_cloud


def test_read_cloud_formats(tmp_path):
    pts = make_object(100, shape_seed=3)
    for name in ("a.ply", "a.pcd", "a.xyz", "a.npy"):
        write_points(tmp_path / name, pts)
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


def _ply(tmp_path, name, points, ascii: bool) -> bytes:
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    o3d.io.write_point_cloud(str(tmp_path / name), cloud, write_ascii=ascii)
    return (tmp_path / name).read_bytes()


@pytest.mark.parametrize("ascii", [True, False], ids=["ascii", "binary"])
def test_damaged_ply_files_are_refused_before_open3d_reads_them(tmp_path, capfd, ascii):
    data = _ply(tmp_path, "whole.ply", make_object(100, shape_seed=1), ascii)
    (tmp_path / "cut.ply").write_bytes(data[: len(data) - 200])
    (tmp_path / "noend.ply").write_bytes(data[: data.index(b"end_header")])
    (tmp_path / "magic.ply").write_bytes(b"plx" + data[3:])
    cases = {"cut.ply": "ends early", "noend.ply": "no end_header", "magic.ply": "not a PLY"}
    for name, message in cases.items():
        with pytest.raises(ValueError, match=f"{name}: damaged or unreadable .ply file.*{message}"):
            read_cloud(tmp_path / name)
    assert len(read_cloud(tmp_path / "whole.ply").points) == 100
    out, err = capfd.readouterr()
    assert out == "" and err == ""  # Open3D's C reader never met the damaged files


def test_read_cloud_from_many_threads_leaves_everyone_s_output_alone(tmp_path, capfd):
    """Reads in threads, a damaged file among them, while another thread prints: every
    read gets its own answer and every line printed meanwhile arrives."""
    import threading
    from concurrent.futures import ThreadPoolExecutor

    clouds = [make_object(300 + 10 * k, shape_seed=k) for k in range(6)]
    paths = [write_points(tmp_path / f"c{k}.ply", c) for k, c in enumerate(clouds)]
    data = (tmp_path / "c0.ply").read_bytes()
    (tmp_path / "bad.ply").write_bytes(data[: len(data) // 2])
    stop = threading.Event()

    def chatter():
        count = 0
        while not stop.is_set():
            print(f"line {count}", flush=True)
            count += 1
        return count

    def read(path):
        try:
            return len(read_cloud(path).points)
        except ValueError as exc:
            return str(exc)

    with ThreadPoolExecutor(8) as pool:
        talker = pool.submit(chatter)
        results = list(pool.map(read, [*paths, str(tmp_path / "bad.ply")] * 5))
        stop.set()
        printed = talker.result()
    assert results[:7] * 5 == results
    assert results[:6] == [len(c) for c in clouds] and "ends early" in results[6]
    out = capfd.readouterr().out.splitlines()
    assert out == [f"line {k}" for k in range(printed)]
    assert o3d.utility.get_verbosity_level() == o3d.utility.VerbosityLevel.Info
