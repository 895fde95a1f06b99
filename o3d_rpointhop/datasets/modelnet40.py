"""ModelNet40 loaders: the official ``modelnet40_ply_hdf5_2048`` release and npz subsets."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ._paths import data_home

__all__ = ["ModelNet40", "load_modelnet40"]

CLASS_NAMES = tuple(
    "airplane bathtub bed bench bookshelf bottle bowl car chair cone cup curtain desk door "
    "dresser flower_pot glass_box guitar keyboard lamp laptop mantel monitor night_stand "
    "person piano plant radio range_hood sink sofa stairs stool table tent toilet tv_stand "
    "vase wardrobe xbox".split()
)


@dataclass
class ModelNet40:
    """Shapes of one ModelNet40 split.

    Attributes
    ----------
    points : ndarray of shape (n_shapes, n_points, 3), float64
    labels : ndarray of shape (n_shapes,), int64
        Index into ``class_names`` (the official ``shape_names.txt`` order).
    class_names : tuple of str
    source : str
        The file or folder the shapes came from.
    names : list of str
        Per shape, where it comes from (``<class>/<shape>`` where known).
    """

    points: np.ndarray
    labels: np.ndarray
    class_names: tuple[str, ...] = CLASS_NAMES
    source: str = ""
    names: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.points)

    def subset(self, mask: np.ndarray) -> ModelNet40:
        """The shapes where ``mask`` (bool or index array) selects."""
        idx = np.arange(len(self))[mask]
        return ModelNet40(
            self.points[idx],
            self.labels[idx],
            self.class_names,
            self.source,
            [self.names[i] for i in idx] if self.names else [],
        )


def normalize_unit_sphere(points: np.ndarray) -> np.ndarray:
    """Centre every shape on its centroid and scale it into the unit sphere."""
    centred = points - points.mean(axis=-2, keepdims=True)
    radius = np.linalg.norm(centred, axis=-1).max(axis=-1)
    return centred / radius[..., None, None]


def load_modelnet40(
    split: str = "train",
    data_dir: str | os.PathLike | None = None,
    *,
    normalize: bool = True,
) -> ModelNet40:
    """Load a ModelNet40 split.

    Parameters
    ----------
    split : {"train", "test"}
    data_dir : path, default=None
        Either the official ``modelnet40_ply_hdf5_2048`` folder (``ply_data_<split>*.h5``
        files; reading them needs ``h5py``), or a folder holding
        ``modelnet40/modelnet40_resampled_<split>_subset.npz`` (the shared data layout),
        or such an ``.npz`` file itself. ``None`` looks in :func:`data_home`.
    normalize : bool, default=True
        Centre each shape and scale it into the unit sphere (the ModelNet40 registration
        convention; the npz subsets are not centred).

    Returns
    -------
    ModelNet40
        2048 points per shape, float64.
    """
    if split not in ("train", "test"):
        raise ValueError(f"split must be 'train' or 'test', got {split!r}")
    root = Path(data_dir).expanduser() if data_dir is not None else data_home()
    if root.is_file():
        data = _load_npz(root)
    elif sorted(root.glob(f"ply_data_{split}*.h5")):
        data = _load_h5(root, split)
    else:
        for candidate in (
            root / "modelnet40" / f"modelnet40_resampled_{split}_subset.npz",
            root / f"modelnet40_resampled_{split}_subset.npz",
        ):
            if candidate.is_file():
                data = _load_npz(candidate)
                break
        else:
            raise FileNotFoundError(
                f"no ModelNet40 {split} data in {root}: expected ply_data_{split}*.h5 files or "
                f"modelnet40/modelnet40_resampled_{split}_subset.npz"
            )
    if normalize:
        data.points = normalize_unit_sphere(data.points)
    return data


def _load_npz(path: Path) -> ModelNet40:
    with np.load(path, allow_pickle=False) as archive:
        points = archive["points"].astype(np.float64)
        labels = archive["labels"].astype(np.int64)
        names = [str(s) for s in archive["source_file"]] if "source_file" in archive else []
        class_names = (
            tuple(str(c) for c in archive["class_names"])
            if "class_names" in archive
            else CLASS_NAMES
        )
    return ModelNet40(points, labels, class_names, str(path), names)


def _load_h5(folder: Path, split: str) -> ModelNet40:
    try:
        import h5py
    except ImportError as exc:
        raise ImportError(
            "reading the official ModelNet40 .h5 files needs h5py: pip install h5py"
        ) from exc
    files = sorted(folder.glob(f"ply_data_{split}*.h5"))
    points, labels = [], []
    for f in files:
        with h5py.File(f, "r") as h5:
            points.append(np.asarray(h5["data"], dtype=np.float64))
            labels.append(np.asarray(h5["label"], dtype=np.int64).reshape(-1))
    names_file = folder / "shape_names.txt"
    class_names = tuple(names_file.read_text().split()) if names_file.is_file() else CLASS_NAMES
    return ModelNet40(np.concatenate(points), np.concatenate(labels), class_names, str(folder), [])
