"""Model files: a plain ``.npz`` of numeric arrays plus JSON metadata, read without pickle.

This module knows the file format, not the estimator: ``_rpointhop.py`` imports it and
hands over the model (or its class); nothing here imports ``_rpointhop.py``.

Layout (format version 4; version 1 files, without the PCA entries and the
``sampling`` and ``n_components`` parameters, version 2 files, without the
``attributes`` parameter, and version 3 files, without the ``pooling`` parameter,
still load)::

    metadata           0-d str array, JSON: format, format_version, library_version,
                       params, n_hops, n_features_out, n_training_clouds, and
                       training_scenes (optional: the scene folders a scene model saw),
                       registration_points (optional: register()'s global cloud size),
                       registration_global_method (optional: register()'s "auto"
                       global step)
    hop{h}_kernels     (n_channels, dim, dim) float32
    hop{h}_means       (n_channels, dim) float32
    hop{h}_energies    (n_channels, dim) float32
    hop{h}_selected    (n_selected,) int64
    pca_components     (k, n_full) float32   only for models fitted with n_components
    pca_variance       (k,) float64
    pca_mean           (n_full,) float64
"""

from __future__ import annotations

import hashlib
import json
import numbers
import zipfile
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from .._version import __version__

FORMAT_NAME = "o3d-rpointhop-model"
FORMAT_VERSION = 4

# Parameters stored in a model file (n_jobs and progress belong to the machine and the
# user, not to the model).
_STORED_PARAMS = (
    "n_neighbors",
    "hop_sizes",
    "lrf_neighbors",
    "attributes",
    "energy_threshold",
    "scale",
    "fit_subsample",
    "sampling",
    "pooling",
    "n_components",
    "random_state",
)


def _model_contents(model: Any) -> tuple[dict, dict]:
    """A fitted ``RPointHopTransformer`` as a model file holds it: its metadata (without
    the library version) and its arrays by entry name, in file order."""
    params = {}
    for name in _STORED_PARAMS:
        value = getattr(model, name)
        if isinstance(value, (tuple, list)):
            value = [v.item() if isinstance(v, np.generic) else v for v in value]
        elif isinstance(value, np.generic):
            value = value.item()
        elif name == "random_state" and not isinstance(value, (numbers.Integral, type(None))):
            value = None  # a RandomState object has no portable form
        params[name] = value
    meta = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "params": params,
        "n_hops": len(model.kernels_),
        "n_features_out": int(model.selected_[-1].size),
        "n_training_clouds": int(model.n_training_clouds_),
    }
    scenes = getattr(model, "training_scenes_", None)
    if scenes is not None:
        meta["training_scenes"] = [str(name) for name in scenes]
    points = getattr(model, "registration_points_", None)
    if points is not None:
        meta["registration_points"] = int(points)
    method = getattr(model, "registration_global_method_", None)
    if method is not None:
        meta["registration_global_method"] = str(method)
    arrays = {}
    for h in range(len(model.kernels_)):
        # float32: the transform applies kernels and means in float32 (the features'
        # precision), so a reloaded model describes exactly as the fitted one, from a
        # file half the size; the energies are only reported.
        arrays[f"hop{h}_kernels"] = np.asarray(model.kernels_[h], dtype=np.float32)
        arrays[f"hop{h}_means"] = np.asarray(model.means_[h], dtype=np.float32)
        arrays[f"hop{h}_energies"] = np.asarray(model.energies_[h], dtype=np.float32)
        arrays[f"hop{h}_selected"] = np.asarray(model.selected_[h], dtype=np.int64)
    if getattr(model, "components_", None) is not None:
        # float32 axes: ample for a projection whose output is float32, half the file.
        arrays["pca_components"] = np.asarray(model.components_, dtype=np.float32)
        arrays["pca_variance"] = np.asarray(model.explained_variance_, dtype=np.float64)
        arrays["pca_mean"] = np.asarray(model.pca_mean_, dtype=np.float64)
    return meta, arrays


def save_model(model: Any, path: str | PathLike) -> None:
    """Write a fitted ``RPointHopTransformer`` to ``path`` (exactly that name)."""
    meta, arrays = _model_contents(model)
    head = {"format": FORMAT_NAME, "format_version": FORMAT_VERSION, "library_version": __version__}
    meta = {**head, **meta}  # the file's key order: format, versions, then the rest
    # Through a file handle: exactly ``path`` (given a name, numpy would append .npz).
    with open(path, "wb") as fh:
        np.savez_compressed(fh, metadata=np.array(json.dumps(meta)), **arrays)


def content_hash(model: Any) -> str:
    """SHA-256 (hex) of what a fitted ``RPointHopTransformer`` describes with: its
    stored parameters (``n_components`` among them), metadata and arrays as a model file
    holds them, the library version left out. Equal for a model and its reloaded file,
    different for the same file on another number of axes."""
    meta, arrays = _model_contents(model)
    digest = hashlib.sha256(json.dumps(meta, sort_keys=True).encode())
    for name, array in arrays.items():
        array = np.ascontiguousarray(array)
        digest.update(f"\0{name}\0{array.dtype.str}\0{array.shape}\0".encode())
        digest.update(array.tobytes())
    return digest.hexdigest()


def _invalid(path, why: str) -> ValueError:
    return ValueError(f"{path} is not a valid {FORMAT_NAME} file: {why}")


def load_model(cls: type, path: str | PathLike) -> Any:
    """An instance of ``cls`` (``RPointHopTransformer``) read from ``path``, no pickle."""
    if not Path(path).is_file():
        raise FileNotFoundError(f"no such model file: {path}")
    try:
        archive = np.load(path, allow_pickle=False)
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise _invalid(path, f"cannot be read as an .npz archive ({exc})") from exc
    if not isinstance(archive, np.lib.npyio.NpzFile):
        raise _invalid(path, "it holds a single array, not an .npz archive")
    try:
        with archive:
            return _from_arrays(cls, path, archive)
    except (zipfile.BadZipFile, EOFError, OSError) as exc:
        raise _invalid(path, f"damaged or incomplete archive ({exc})") from exc


def _entry(path, archive, key: str) -> np.ndarray:
    """One array of the archive, refusing anything that would need pickle."""
    if key not in archive.files:
        raise _invalid(path, f"no {key!r} entry")
    try:
        return archive[key]
    except ValueError as exc:  # object arrays: numpy refuses them without pickle
        raise _invalid(path, f"entry {key!r} would need pickle to load ({exc})") from exc


def _from_arrays(cls: type, path, archive) -> Any:
    try:
        meta = json.loads(str(_entry(path, archive, "metadata")[()]))
    except (ValueError, TypeError) as exc:
        raise _invalid(path, f"metadata is not JSON ({exc})") from exc
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
        raise _invalid(path, "its metadata does not name this format")
    version = meta.get("format_version")
    if not isinstance(version, int) or version < 1:
        raise _invalid(path, f"bad format_version {version!r}")
    if version > FORMAT_VERSION:
        raise ValueError(
            f"{path} uses model format version {version}, but this o3d-rpointhop "
            f"({__version__}) reads up to version {FORMAT_VERSION}; upgrade o3d-rpointhop"
        )
    params = dict(meta.get("params", {}))
    unknown = set(params) - set(_STORED_PARAMS)
    if unknown:
        raise _invalid(path, f"unknown parameters {sorted(unknown)}")
    for name in ("n_neighbors", "hop_sizes", "attributes"):
        if name in params and isinstance(params[name], list):
            params[name] = tuple(params[name])
    model = cls(**params)
    model._validate_params()  # the stored parameters, as a fit would check them
    config = model._hop_config()
    n_hops = meta.get("n_hops")
    if n_hops != config.n_hops:
        raise _invalid(path, f"n_hops={n_hops!r} does not match n_neighbors")
    kernels, means, energies, selected = [], [], [], []
    n_channels = 1
    for h in range(n_hops):
        dim = config.hop1_dim if h == 0 else 8
        k, b, e, s = (
            _entry(path, archive, f"hop{h}_{name}")
            for name in ("kernels", "means", "energies", "selected")
        )
        if k.shape != (n_channels, dim, dim) or b.shape != e.shape or e.shape != (n_channels, dim):
            raise _invalid(path, f"hop {h + 1} arrays have inconsistent shapes")
        if not (np.isfinite(k).all() and np.isfinite(b).all() and np.isfinite(e).all()):
            raise _invalid(path, f"hop {h + 1} holds non-finite values")
        if s.ndim != 1 or s.size == 0 or not np.issubdtype(s.dtype, np.integer):
            raise _invalid(path, f"hop {h + 1} has no valid channel selection")
        if s.min() < 0 or s.max() >= n_channels * dim or np.any(np.diff(s) <= 0):
            raise _invalid(path, f"hop {h + 1} selects channels out of range")
        kernels.append(k.astype(np.float64))
        means.append(b.astype(np.float64))
        energies.append(e.astype(np.float64))
        selected.append(s.astype(np.int64))
        n_channels = s.size
    if meta.get("n_features_out") != n_channels:
        raise _invalid(path, "n_features_out does not match the last hop")
    model.kernels_, model.means_, model.energies_, model.selected_ = (
        kernels,
        means,
        energies,
        selected,
    )
    model.components_ = model.explained_variance_ = model.pca_mean_ = None
    if "pca_components" in archive.files:
        axes, variance, mean = (
            _entry(path, archive, key) for key in ("pca_components", "pca_variance", "pca_mean")
        )
        if (
            axes.ndim != 2
            or axes.shape[1] != n_channels
            or variance.shape != (len(axes),)
            or (mean.shape != (n_channels,))
        ):
            raise _invalid(path, "its principal axes do not match the last hop")
        if not all(np.isfinite(a).all() for a in (axes, variance, mean)):
            raise _invalid(path, "its principal axes hold non-finite values")
        model.components_ = axes.astype(np.float64)
        model.explained_variance_ = variance.astype(np.float64)
        model.pca_mean_ = mean.astype(np.float64)
    model.n_features_in_ = 3
    model.n_training_clouds_ = int(meta.get("n_training_clouds", 0))
    scenes = meta.get("training_scenes")
    if scenes is not None:
        if not (isinstance(scenes, list) and all(isinstance(x, str) for x in scenes)):
            raise _invalid(path, "training_scenes is not a list of names")
        model.training_scenes_ = list(scenes)
    points = meta.get("registration_points")
    if points is not None:
        if not (isinstance(points, int) and not isinstance(points, bool) and points >= 3):
            raise _invalid(path, "registration_points is not a count of at least 3")
        model.registration_points_ = points
    method = meta.get("registration_global_method")
    if method is not None:
        if not isinstance(method, str):
            raise _invalid(path, "registration_global_method is not a name")
        model.registration_global_method_ = method
    model._projection()  # n_components within the stored axes
    return model
