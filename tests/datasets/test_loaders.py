"""Dataset loaders on files laid out as the official releases."""

from __future__ import annotations

import numpy as np
import pytest


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
