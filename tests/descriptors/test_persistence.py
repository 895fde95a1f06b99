"""Model files: save and load round trips, pickle and joblib, and files refused without
pickle."""

from __future__ import annotations

import pickle

import joblib
import numpy as np
import pytest

from o3d_rpointhop import RPointHopTransformer


def _rewrite(src, dst, **changes):
    with np.load(src, allow_pickle=False) as archive:
        arrays = {k: archive[k] for k in archive.files}
    arrays.update(changes)
    np.savez(dst, **arrays)


# ----------------------------------------------------------------------------- persistence
def test_save_load_round_trip(fitted, cloud, tmp_path):
    path = tmp_path / "model.npz"
    fitted.save(path)
    loaded = RPointHopTransformer.load(path)
    assert loaded.get_params() == {**fitted.get_params(), "n_jobs": None}
    np.testing.assert_array_equal(loaded.transform(cloud), fitted.transform(cloud))
    with np.load(path, allow_pickle=False) as archive:  # readable without pickle
        assert "metadata" in archive.files


def test_joblib_and_pickle_round_trip(fitted, cloud, tmp_path):
    joblib.dump(fitted, tmp_path / "m.joblib")
    np.testing.assert_array_equal(
        joblib.load(tmp_path / "m.joblib").transform(cloud), fitted.transform(cloud)
    )
    np.testing.assert_array_equal(
        pickle.loads(pickle.dumps(fitted)).transform(cloud), fitted.transform(cloud)
    )


def test_load_rejects_foreign_and_damaged_files(fitted, tmp_path):
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, a=np.arange(3))
    with pytest.raises(ValueError, match="not a valid o3d-rpointhop-model file"):
        RPointHopTransformer.load(foreign)

    text = tmp_path / "text.npz"
    text.write_text("hello")
    with pytest.raises(ValueError, match="cannot be read"):
        RPointHopTransformer.load(text)

    good = tmp_path / "good.npz"
    fitted.save(good)
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(ValueError, match="not a valid"):
        RPointHopTransformer.load(truncated)

    with pytest.raises(FileNotFoundError):
        RPointHopTransformer.load(tmp_path / "missing.npz")


def test_load_rejects_newer_format_and_inconsistent_arrays(fitted, tmp_path):
    import json

    good = tmp_path / "good.npz"
    fitted.save(good)
    with np.load(good, allow_pickle=False) as archive:
        meta = json.loads(str(archive["metadata"]))
    newer = tmp_path / "newer.npz"
    _rewrite(good, newer, metadata=np.array(json.dumps({**meta, "format_version": 99})))
    with pytest.raises(ValueError, match="format version 99.*upgrade"):
        RPointHopTransformer.load(newer)

    broken = tmp_path / "broken.npz"
    _rewrite(good, broken, hop1_kernels=np.zeros((3, 8, 8)))
    with pytest.raises(ValueError, match="inconsistent shapes"):
        RPointHopTransformer.load(broken)

    nan = tmp_path / "nan.npz"
    kernels = np.load(good)["hop0_kernels"].copy()
    kernels[0, 0, 0] = np.nan
    _rewrite(good, nan, hop0_kernels=kernels)
    with pytest.raises(ValueError, match="non-finite"):
        RPointHopTransformer.load(nan)

    pickled = tmp_path / "pickled.npz"
    _rewrite(good, pickled, hop0_selected=np.array([object()], dtype=object))
    with pytest.raises(ValueError, match="not a valid.*pickle"):
        RPointHopTransformer.load(pickled)


def test_save_needs_a_fitted_model(tmp_path):
    from sklearn.exceptions import NotFittedError

    with pytest.raises(NotFittedError):
        RPointHopTransformer().save(tmp_path / "m.npz")


def test_model_files_hold_float32_kernels_and_describe_as_the_fitted_model(fitted, cloud, tmp_path):
    """The transform applies kernels and means in float32, so storing them so is exact."""
    fitted.save(tmp_path / "m.npz")
    with np.load(tmp_path / "m.npz", allow_pickle=False) as archive:
        for h in range(len(fitted.kernels_)):
            for name in ("kernels", "means", "energies"):
                assert archive[f"hop{h}_{name}"].dtype == np.float32
    loaded = RPointHopTransformer.load(tmp_path / "m.npz")
    assert loaded.kernels_[0].dtype == np.float64
    np.testing.assert_array_equal(loaded.transform(cloud), fitted.transform(cloud))


def test_shipped_model_files_stay_under_a_megabyte():
    from o3d_rpointhop.descriptors import PRETRAINED_MODELS
    from o3d_rpointhop.descriptors._pretrained import pretrained_path

    for name in PRETRAINED_MODELS:
        with pretrained_path(name) as path:
            assert path.stat().st_size < 1_000_000, name
