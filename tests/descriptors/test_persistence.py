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


def _metadata(path):
    import json

    with np.load(path, allow_pickle=False) as archive:
        return json.loads(str(archive["metadata"]))


def _meta_change(**changes):
    def change(meta, arrays):
        meta.update(changes)

    return change


def _array_change(key, edit):
    def change(meta, arrays):
        arrays[key] = edit(arrays[key].copy())

    return change


def _with_axes(edit):
    def change(meta, arrays):
        width = meta["n_features_out"]
        arrays.update(
            pca_components=np.eye(2, width),
            pca_variance=np.ones(2),
            pca_mean=np.zeros(width),
        )
        edit(arrays)

    return change


def _shuffle(selected):
    return selected[::-1]


def _nan_mean(arrays):
    arrays["pca_mean"] = np.full_like(arrays["pca_mean"], np.nan)


@pytest.mark.parametrize(
    "change, message",
    [
        (_meta_change(format="another"), "metadata does not name this format"),
        (_meta_change(format_version=0), "bad format_version 0"),
        (
            _meta_change(params={"n_neighbors": [64], "colour": 1}),
            r"unknown parameters \['colour'\]",
        ),
        (_meta_change(n_hops=3), "n_hops=3 does not match n_neighbors"),
        (_meta_change(n_features_out=7), "n_features_out does not match the last hop"),
        (_meta_change(training_scenes="kitchen"), "training_scenes is not a list of names"),
        (_array_change("hop0_selected", lambda s: s.astype(np.float64)), "no valid channel"),
        (_array_change("hop0_selected", _shuffle), "selects channels out of range"),
        (_array_change("hop1_selected", lambda s: s + 10_000), "selects channels out of range"),
        (_with_axes(lambda a: a.update(pca_variance=np.ones(3))), "axes do not match"),
        (_with_axes(_nan_mean), "principal axes hold non-finite values"),
    ],
    ids=[
        "format",
        "version",
        "parameter",
        "hops",
        "width",
        "scenes",
        "selection-dtype",
        "selection-order",
        "selection-range",
        "axes-shape",
        "axes-nan",
    ],
)
def test_each_inconsistency_of_a_model_file_is_named(fitted, tmp_path, change, message):
    import json

    good = tmp_path / "good.npz"
    fitted.save(good)
    meta = _metadata(good)
    with np.load(good, allow_pickle=False) as archive:
        arrays = {k: archive[k] for k in archive.files}
    change(meta, arrays)
    arrays["metadata"] = np.array(json.dumps(meta))
    np.savez(tmp_path / "bad.npz", **arrays)
    with pytest.raises(ValueError, match=f"not a valid o3d-rpointhop-model file.*{message}"):
        RPointHopTransformer.load(tmp_path / "bad.npz")


def test_an_archive_of_one_array_is_refused(tmp_path):
    np.save(tmp_path / "one.npy", np.arange(3))
    with pytest.raises(ValueError, match="single array, not an .npz archive"):
        RPointHopTransformer.load(tmp_path / "one.npy")


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
